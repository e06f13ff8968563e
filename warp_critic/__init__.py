"""warp-critic: model-based meta-learning of critics for policy gradients on Newton/Warp.

Data flow: scene (USD) -> simulator (Newton worlds) -> bridge (warp<->torch autograd) -> rollout ->
networks / losses -> inner update -> outer update -> training loop -> recording.
"""

__version__ = "0.1.0"
