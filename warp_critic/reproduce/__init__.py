"""``warp-critic reproduce``: the paper's experiments end to end, resumable stage by stage, and a report.

Modules: :mod:`~warp_critic.reproduce.experiments.settings` (paper and ``--quick`` settings, hashes), :mod:`~warp_critic.reproduce.engine.stages` (stage directories,
``stage.json``, the output marker), :mod:`~warp_critic.reproduce.experiments.analyses` (toy, landscape), :mod:`~warp_critic.reproduce.experiments.metatrain`
(meta-training of the three methods, every seed batched), :mod:`~warp_critic.reproduce.experiments.evaluate` (batched meta-test: many
runs, goals and dynamics variants in one model), :mod:`~warp_critic.reproduce.experiments.generalize` (KUKA tables, reacher maps),
:mod:`~warp_critic.reproduce.experiments.reach` (open-loop reachability floors), :mod:`.report` (REPORT.md, results.json, figures,
report.rrd) with its sections :mod:`.report_analyses` (toy, landscapes), :mod:`.report_training`
(Figure 3), :mod:`.report_maps` (Figures 4-6) and :mod:`.report_tables` (the KUKA tables), sharing a
:mod:`.report_draft`, and :mod:`.report_plots` (figures) and :mod:`.report_paper` (steps to error
levels, solved seeds, 2-D maps, verdicts), :mod:`~warp_critic.reproduce.engine.executors` (in process, local processes) and
:mod:`~warp_critic.reproduce.engine.on_ray` (Ray), chosen by the flags in :mod:`~warp_critic.reproduce.engine.choose_executor`, :mod:`~warp_critic.reproduce.experiments.validate` (every
``--set`` checked up front), :mod:`.pipeline` (the order), :mod:`~warp_critic.reproduce.experiments.units` (each stage's function and
inputs). The flags live in :mod:`warp_critic.cli.reproduce`.
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
