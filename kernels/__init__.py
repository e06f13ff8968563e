"""Warp kernels of warp-critic, installed as ``warp_critic.kernels``.

``kinematics``: end-effector tip positions of all worlds from Newton's body poses (used for
recordings and analyses, one launch for every world).
"""
