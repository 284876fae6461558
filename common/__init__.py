"""The leaves below everything: atomic writes, units, peak memory, logging set-up and project paths.

Every other package may import these modules, and they import no project module themselves
(tests/test_import_rules.py keeps them at the bottom of the package order)."""
