"""Warp kernels of warp-critic, installed as ``warp_critic.kernels``.

Kernels sit in small modules next to the Python that launches them conceptually:
``state_io`` packs torch tensors into Newton's per-world state arrays and checks them for
non-finite values.
"""
