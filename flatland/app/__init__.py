"""The application layer shared by both packages: command line, study runner, tables, figures.

Built on the numeric kernel :mod:`flatland.core` and told about a package only
through its :class:`~flatland.app.cli.Package` description (built by the package's
``__main__``): :mod:`flatland.app.cli` (``python -m flatland``, ``python -m sphere3d``),
:mod:`flatland.app.study` and :mod:`flatland.app.study_config` (method × option ×
trial grids against a reference), :mod:`flatland.app.table` (text tables) and
:mod:`flatland.app.plotting` (matplotlib figures, imported when a figure is drawn).
"""
