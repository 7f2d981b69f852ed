"""The compiled rules (`iout_mj/**/*.c`, built into `iout_mj._native` by the package's build):
loading, the pointer structs the C code reads, and the layout check.

The C library is loaded with ctypes (no Python API in C, nothing to JIT): each layer states
its rules in Python docstrings and calls its C functions through the structs built here,
whose field orders are the Python declarations'. `require_layout` refuses a library whose
structs were declared in another order (a stale build), instead of reading wrong memory.
"""

from __future__ import annotations

import ctypes
import importlib.util
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

LIBRARY = "iout_mj._native"


def _load() -> ctypes.CDLL:
    spec = importlib.util.find_spec(LIBRARY)
    if spec is None or spec.origin is None:
        raise ImportError(
            f"{LIBRARY}, the compiled mission rules, is not built: install the package "
            "(`make setup`, or `pip install -e .`), which compiles iout_mj/**/*.c with the "
            "system's C compiler"
        )
    built = Path(spec.origin)
    package = Path(__file__).parent
    if (package.parent / "pyproject.toml").exists():  # a source checkout: is the build current?
        sources = [package / "native.h", *package.glob("*/*.c")]
        stale = [s.name for s in sources if s.stat().st_mtime > built.stat().st_mtime]
        if stale:
            raise ImportError(
                f"{built.name} is older than {', '.join(stale)}: rebuild it (`make setup`, or "
                "`pip install -e .`)"
            )
    return ctypes.CDLL(str(built))


lib = _load()
"""The C library (functions declared in `iout_mj/native.h`)."""

P = ctypes.c_void_p
I64 = ctypes.c_int64
F64 = ctypes.c_double
_SIGNATURES: dict[str, tuple[Any, list[Any]]] = {
    "iout_layout": (ctypes.c_char_p, []),
    "iout_link_energies_each": (None, [P, P, I64, P, P]),
    "iout_jain": (F64, [P, I64]),
    "iout_summarise": (None, [P, I64, I64]),
    "iout_serve": (None, [P, I64, I64, I64, P, I64, F64, P, P, P, I64, P, P, P, P, P, P, P]),
    "iout_first_bad_action": (I64, [P, I64, P, I64]),
    "iout_begin_slot": (None, [P]),
    "iout_end_slot": (None, [P]),
    "iout_start": (None, [P, P]),
    "iout_observe": (None, [P]),
    "iout_unserved_aoi_sum": (F64, [P, I64, P, I64]),
    "iout_node_energy_levels": (None, [P, I64, F64, F64, P]),
    "iout_kinematic_slot": (None, [P]),
}
for _name, (_result, _args) in _SIGNATURES.items():
    getattr(lib, _name).restype = _result
    getattr(lib, _name).argtypes = _args


def address(a: np.ndarray) -> int:
    """The data pointer of a C-contiguous array (checked: the C code assumes it)."""
    if not a.flags.c_contiguous:
        raise ValueError("the compiled rules need C-contiguous arrays")
    return int(a.ctypes.data)


def pointers(name: str, fields: Iterable[str]) -> type[ctypes.Structure]:
    """A ctypes struct of one pointer per field, in order (the C struct of that name)."""
    return type(name, (ctypes.Structure,), {"_fields_": [(f, P) for f in fields]})


def fill(struct: ctypes.Structure, arrays: Any) -> None:
    """Point every field of `struct` at the array of the same name in `arrays` (a namedtuple)."""
    for field in struct._fields_:
        setattr(struct, field[0], address(getattr(arrays, field[0])))


def require_layout(layout: str) -> None:
    """Refuse a library whose structs are declared in another order than `layout`."""
    built = lib.iout_layout().decode()
    if built != layout:
        raise ImportError(
            f"{LIBRARY} was built from other struct declarations than this source; rebuild it "
            f"(`pip install -e .`). Built: {built!r}; expected: {layout!r}"
        )
