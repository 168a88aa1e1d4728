"""One parameter of a protocol's or a run's dataclass, stated once (its default, its help line,
its folder-name abbreviation and its range), for :class:`rodwarp.experiments.ProtocolParams`
and the command line built from it."""

from __future__ import annotations

from rodwarp._util import option
from rodwarp.validation import Range


def param(default, help: str, short: str | None = None, range: Range | None = None, **metadata):
    """A parameter field: its default, its ``rodwarp simulate --help`` line, its abbreviation in
    default folder names (:func:`~rodwarp.experiments.default_run_name`; the name when None) and
    the :class:`~rodwarp.validation.Range` of values it takes (checked by
    :meth:`ProtocolParams.validate` and the CLI alike)."""
    return option(default, help, short=short, range=range, **metadata)
