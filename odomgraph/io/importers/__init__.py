"""Importers: other datasets' files -> a log directory (LOG_FORMAT.md).

Each importer is a function ``import_<kind>(source, ...) -> Log``; the CLI
writes the Log with ``odomgraph.io.log.write_log``.
"""
