"""Sweep analysis: read a sweep's runs from MLflow and write the paper's figures and tables.

    python -m analysis.report EXPERIMENT [--tracking-uri URI] [--out DIR]

Modules: `load` (MLflow -> Sweep/Trial), `stats` (IQM, bootstrap CIs, interpolation, steps to a
threshold), `aggregate` (trials -> per-configuration summaries and the list of what is missing),
`tables` (CSV/Markdown), `figures` (PNG), `report` (the CLI).
"""
