"""The application layer shared by both packages: command line, study runner, tables, figures.

Built on the numeric kernel :mod:`flatland.core` and told about a package only
through its :class:`~flatland.app.cli.Package` description (built by the package's
``__main__``): :mod:`flatland.app.cli` (``python -m flatland``, ``python -m sphere3d``),
:mod:`flatland.app.study` (method × option × trial grids against a reference: the
runner, with :mod:`~flatland.app.study_config`, :mod:`~flatland.app.study_trials`,
:mod:`~flatland.app.study_reference` and :mod:`~flatland.app.study_result`),
:mod:`flatland.app.table` (text tables); the verbs of the command line are in
:mod:`flatland.app.commands`. Figures are drawn by :mod:`flatland.plotting`,
imported when a figure is drawn.
"""
