"""``warp-critic reproduce``: the paper's experiments end to end, resumable stage by stage, and a report.

Modules: :mod:`.settings` (paper and ``--quick`` settings, hashes), :mod:`.stages` (stage directories,
``stage.json``, the output marker), :mod:`.analyses` (toy, landscape), :mod:`.training` (meta-training
of the three methods, every seed batched), :mod:`.evaluate` (batched meta-test: many runs, goals and
dynamics variants in one model), :mod:`.generalize` (KUKA tables, reacher maps), :mod:`.report`
(REPORT.md, results.json, figures, report.rrd), :mod:`.pipeline` (the order), :mod:`.cli` (flags).
"""
