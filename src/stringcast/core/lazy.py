"""Lazy package faces (PEP 562): a stage package names its public functions, but importing the
package loads none of its modules; each loads when one of its names is first used.

Every workflow rule is a new process, and a stage that imported all of its package (and so
SciPy's optimizers, pandas, numba, ...) before its first line of work paid up to 0.3 s of
import on the trial's critical path. With lazy faces a stage loads what it runs.
"""
from __future__ import annotations

import importlib
import sys
from collections.abc import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> tuple[Callable[[str], object], Callable[[], list]]:
    """A package's ``__getattr__`` and ``__dir__`` for ``exports`` {name: relative module}.

    Use in a package's ``__init__``::

        __getattr__, __dir__ = lazy_exports(__name__, {"run_sync": ".offset", ...})

    with the same imports under ``if TYPE_CHECKING:`` for readers and linters.

    Raises (from ``__getattr__``):
        AttributeError: a name the package does not export.
    """

    def __getattr__(name: str):
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module, package), name)
        setattr(sys.modules[package], name, value)   # later uses skip this function
        return value

    def __dir__() -> list:
        return sorted(set(exports) | set(vars(sys.modules[package])))

    return __getattr__, __dir__
