"""Optional dependencies (pyproject's extras), imported when a feature needs them.

A missing one is an :class:`~meshlab_sharp.errors.InputError` naming the feature and
the extra that installs it, never an ``ImportError`` traceback.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from .errors import InputError

__all__ = ["require"]


def require(module: str, purpose: str, extra: str) -> ModuleType:
    """Import ``module`` (dotted names allowed), or raise a one-line error.

    Parameters
    ----------
    module : str
        The module to import, e.g. ``"laspy"`` or ``"dask.distributed"``.
    purpose : str
        What needs it, for the message: ``"reading LAS/LAZ"``.
    extra : str
        The extra of ``meshlab-sharp`` that installs it: ``"las"``.

    Raises
    ------
    InputError
        ``"reading LAS/LAZ needs laspy: pip install 'meshlab-sharp[las]'"``.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(
            f"{purpose} needs {module.split('.')[0]}: pip install 'meshlab-sharp[{extra}]'"
        ) from None
