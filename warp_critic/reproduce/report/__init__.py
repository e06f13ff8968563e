"""Report: the verdict rules and the report's sections, computed from the stage records into ``REPORT.md``, ``results.json``, figures and ``report.rrd``."""
