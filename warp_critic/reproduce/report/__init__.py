"""Report: the verdict rules and the report's sections, computed from the stage records into ``results.json`` and rendered from it into ``REPORT.md``, with figures and ``report.rrd``.

Each section is a pure ``compute(Inputs) -> dict`` and ``render(view) -> list[str]`` pair
(:mod:`~warp_critic.reproduce.report.section` states the contract); :mod:`~warp_critic.reproduce.report.write`
lists them in order in ``SECTIONS`` and renders ``REPORT.md`` from the ``results.json`` text it wrote.
"""
