"""Public names of a package imported on first access (PEP 562), for light package imports.

A package lists ``{public name: submodule}`` and installs the pair of module functions this returns:
``import fmus_src.nck`` then loads nothing heavy, and ``fmus_src.nck.NCKernel`` imports ``.component``
(and its numba kernels) on first use, once.
"""
from __future__ import annotations

import importlib
from typing import Any, Callable


def lazy_exports(package: str, table: dict[str, str], namespace: dict[str, Any],
                 public: list[str]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """Module ``__getattr__`` and ``__dir__`` that import ``table``'s names from their submodules on first access.

    Parameters
    ----------
    package : str
        The package's ``__name__`` (relative submodules are resolved against it).
    table : dict
        Public name -> submodule that defines it, relative (``".planner"``).
    namespace : dict
        The package's ``globals()``: a name, once imported, is stored there, so later lookups are plain.
    public : list of str
        The package's ``__all__``.

    Returns
    -------
    (getattr, dir)
        To assign to the package's ``__getattr__`` and ``__dir__``. An unknown name raises AttributeError
        naming the package, as for any module.
    """
    def module_getattr(name: str) -> Any:
        module = table.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module, package), name)
        namespace[name] = value
        return value

    def module_dir() -> list[str]:
        return sorted(set(namespace) | set(public))

    return module_getattr, module_dir
