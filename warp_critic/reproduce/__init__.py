"""``warp-critic reproduce``: the paper's experiments end to end, resumable stage by stage, and a report.

Three layers, each importing only the ones before it (``tests/test_layers.py``):

* :mod:`~warp_critic.reproduce.engine`: a general stage workflow that knows no paper and no method
  -- :mod:`~warp_critic.reproduce.engine.stages` (stage directories, ``stage.json``, the output
  marker), the executors (:mod:`~warp_critic.reproduce.engine.executors`: in process, local
  processes; :mod:`~warp_critic.reproduce.engine.on_ray`: Ray; chosen by the flags in
  :mod:`~warp_critic.reproduce.engine.choose_executor`), :mod:`~warp_critic.reproduce.engine.ledger`
  (the calls on a folder) and :mod:`~warp_critic.reproduce.engine.carry` (stages to another machine).
* :mod:`~warp_critic.reproduce.experiments`: the paper's stages -- settings (paper and ``--quick``,
  hashes), recipes, validation (every ``--set`` checked up front), the plan
  (:mod:`~warp_critic.reproduce.experiments.plan`), each stage's function and inputs
  (:mod:`~warp_critic.reproduce.experiments.units`: toy, landscape, meta-training, the reacher maps
  and KUKA tables with batched meta-test and open-loop reachability floors).
* :mod:`~warp_critic.reproduce.report`: the verdict rules and the report's sections, written by
  :mod:`~warp_critic.reproduce.report.write` (REPORT.md, results.json, figures, report.rrd).

:mod:`~warp_critic.reproduce.pipeline` joins them: it runs the stages a call needs, then writes the
report. The flags live in :mod:`warp_critic.cli.reproduce`.
"""

from warp_critic.core.exports import lazy_exports

__all__, __getattr__, __dir__ = lazy_exports(
    __name__,
    {
        "warp_critic.reproduce.experiments.plan": ("ReproduceConfig",),
        "warp_critic.reproduce.pipeline": ("reproduce",),
        "warp_critic.reproduce.engine.executors": ("InProcess", "LocalProcesses"),
        "warp_critic.reproduce.engine.choose_executor": ("make_executor",),
        "warp_critic.reproduce.engine.on_ray": ("RayExecutor",),
    },
)
