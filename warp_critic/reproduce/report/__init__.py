"""Report: the verdict rules and the report's sections, computed from the stage records into ``results.json``; ``REPORT.md``, figures and ``report.rrd`` written from it."""
