"""The compiled rules (`iout_mj/native.c`, `iout_mj/*/*.c`, built into `iout_mj._native`):
loading, the views Python builds from the library's own layout, and checked calls.

`native.h` declares every struct, reward term and observation group once, as X-macro lists
that expand to the C structs and to a table of names, types, offsets and sizes compiled into
the library. This module reads that table and builds every view from it by name and offset
(`record_dtype`, `struct_type`): a field moved in `native.h` moves here too, and a field that
Python does not have, or has with another element type, fails at import (`require_fields`).
Every exported C function checks what it is handed and returns a status; `call` turns a
refusal into `NativeError` (or `ActionError` for an action index) with C's message. The C
code holds addresses only, so every array it points to is allocated here (`allocate`) and
owned by an object whose attributes cannot be rebound (`Frozen`).
"""

from __future__ import annotations

import ctypes
import importlib.util
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from iout_mj.errors import IoutError

LIBRARY = "iout_mj._native"
SOURCES = ("native.h", "native.c", "*/*.c")
"""The library's sources, relative to the package (globs)."""


class NativeError(IoutError, ValueError):
    """The compiled rules refused what they were handed (the message says what and why)."""


class ActionError(NativeError):
    """An action outside the action space (the message names the AUV, field and range)."""


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
        sources = [s for pattern in SOURCES for s in package.glob(pattern)]
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
_SIGNATURES: dict[str, list[Any]] = {
    "iout_decls": [P],
    "iout_groups": [P],
    "iout_tokens": [P],
    "iout_terms": [P],
    "iout_link_energies": [P, P, I64, P, P],
    "iout_link_pair_energies": [P, P, P, P, I64, P, P],
    "iout_summarise": [P, I64, I64],
    "iout_serve": [P, I64, I64, I64, I64, P, I64, F64, P, P, P, I64, P, P, P, P, P, P, P],
    "iout_serve_channel": [P, I64, I64, I64, I64, P, P, I64, F64, *[P] * 13],
    "iout_packet_error_rates": [P, P, I64, P],
    "iout_tl_interpolate": [P, I64, P, I64, P, P, P, I64, P],
    "iout_francois_garrison": [P, I64, F64, F64, F64, F64, P],
    "iout_begin_slot": [P],
    "iout_end_slot": [P],
    "iout_start": [P, P],
    "iout_observe": [P],
    "iout_unserved_aoi_sum": [P, I64, P, I64, P],
    "iout_node_energy_levels": [P, I64, F64, F64, P],
    "iout_kinematic_slot": [P],
    "iout_observe_tokens": [P, I64, F64, P, I64],
}
"""Every exported function returns an int64 status (0: done)."""
for _name, _args in _SIGNATURES.items():
    getattr(lib, _name).restype = I64
    getattr(lib, _name).argtypes = _args
lib.iout_error.restype = ctypes.c_char_p
lib.iout_error.argtypes = []
_EACTION = 2
"""native.h's IOUT_EACTION."""


def call(function: Any, *args: Any) -> None:
    """Call a checked C function (`lib.iout_*`); a refusal raises with C's message."""
    status = function(*args)
    if status:
        text = lib.iout_error().decode()
        raise (ActionError if status == _EACTION else NativeError)(text)


# ---------------------------------------------------------------------------- declarations
class Decl(NamedTuple):
    """One field of a struct as the compiled library declares it."""

    owner: str
    name: str
    type: str
    """C element type: 'double', 'int64_t', 'bool', or a struct name ('const ' dropped)."""
    kind: str
    """'value', 'array' (a fixed-size array of values), 'pointer' or 'struct'."""
    offset: int
    size: int
    """Bytes (an array's: all its elements)."""

    @property
    def elements(self) -> int:
        """Elements of an array field (1 for a value)."""
        return self.size // ELEMENT_DTYPES[self.type].itemsize if self.kind == "array" else 1


class _CDecl(ctypes.Structure):
    _fields_ = [
        ("owner", ctypes.c_char_p),
        ("name", ctypes.c_char_p),
        ("type", ctypes.c_char_p),
        ("kind", ctypes.c_char_p),
        ("offset", ctypes.c_int64),
        ("size", ctypes.c_int64),
    ]


class _CGroup(ctypes.Structure):
    _fields_ = [
        ("name", ctypes.c_char_p),
        ("per_auv", ctypes.c_int64),
        ("per_node", ctypes.c_int64),
        ("per_pair", ctypes.c_int64),
        ("fixed", ctypes.c_int64),
    ]


class _CToken(ctypes.Structure):
    _fields_ = [
        ("part", ctypes.c_char_p),
        ("name", ctypes.c_char_p),
        ("fixed", ctypes.c_int64),
        ("per_auv", ctypes.c_int64),
    ]


class TokenEntry(NamedTuple):
    """An entry of a token of the token observation as the compiled library declares it:
    `fixed + per_auv * M` values, M = N - 1 in an AUV token, N in a node token."""

    part: str
    """'global', 'auv' or 'node'."""
    name: str
    fixed: int
    per_auv: int


class Group(NamedTuple):
    """An observation group as the compiled library declares it: its size is
    per_auv N + per_node K + per_pair N K + fixed."""

    name: str
    per_auv: int
    per_node: int
    per_pair: int
    fixed: int


def _table(function: Any, row: type[ctypes.Structure]) -> list[Any]:
    pointer = ctypes.POINTER(row)()
    count = function(ctypes.byref(pointer))
    return [pointer[i] for i in range(count)]


def read_layout(library: ctypes.CDLL) -> tuple[dict[str, list[Decl]], dict[str, int]]:
    """The fields of every struct (in offset order) and every struct's size, as `library` was
    compiled."""
    library.iout_decls.restype = I64
    fields: dict[str, list[Decl]] = {}
    sizes: dict[str, int] = {}
    for d in _table(library.iout_decls, _CDecl):
        owner, kind = d.owner.decode(), d.kind.decode()
        if kind == "sizeof":
            sizes[owner] = d.size
            continue
        ctype = d.type.decode().removeprefix("const ")
        fields.setdefault(owner, []).append(
            Decl(owner, d.name.decode(), ctype, kind, d.offset, d.size)
        )
    return {k: sorted(v, key=lambda f: f.offset) for k, v in fields.items()}, sizes


FIELDS, SIZES = read_layout(lib)
"""The compiled library's structs: their fields and sizes."""
GROUPS = tuple(
    Group(g.name.decode(), g.per_auv, g.per_node, g.per_pair, g.fixed)
    for g in _table(lib.iout_groups, _CGroup)
)
"""The observation groups, in order (native.h's IOUT_OBSERVATION)."""
TOKENS = tuple(
    TokenEntry(t.part.decode(), t.name.decode(), t.fixed, t.per_auv)
    for t in _table(lib.iout_tokens, _CToken)
)
"""The entries of the token observation, in order (native.h's IOUT_TOKENS)."""
_terms = ctypes.POINTER(ctypes.c_char_p)()
REWARD_TERMS = tuple(_terms[i].decode() for i in range(lib.iout_terms(ctypes.byref(_terms))))
"""The reward terms, in the order of the mission's term array (IOUT_REWARD_TERMS)."""

ELEMENT_DTYPES = {
    "double": np.dtype(np.float64),
    "int64_t": np.dtype(np.int64),
    "bool": np.dtype(bool),
    "_Bool": np.dtype(bool),  # what `bool` expands to before the table stringifies it
}
_CTYPES: dict[str, Any] = {"double": ctypes.c_double, "int64_t": ctypes.c_int64}


def record_dtype(owner: str) -> np.dtype:
    """The numpy record of a struct of values and fixed-size arrays (Params, Link), at the
    library's offsets."""
    fields = FIELDS[owner]
    return np.dtype(
        {
            "names": [f.name for f in fields],
            "formats": [
                (ELEMENT_DTYPES[f.type], (f.elements,))
                if f.kind == "array"
                else ELEMENT_DTYPES[f.type]
                for f in fields
            ],
            "offsets": [f.offset for f in fields],
            "itemsize": SIZES[owner],
        }
    )


_STRUCTS: dict[str, type[ctypes.Structure]] = {}


def struct_type(owner: str) -> type[ctypes.Structure]:
    """The ctypes struct of `owner` (pointers as addresses, nested structs built likewise),
    checked field by field against the library's offsets and size."""
    if owner in _STRUCTS:
        return _STRUCTS[owner]
    members: list[tuple[str, Any]] = []
    for f in FIELDS[owner]:
        if f.kind == "pointer":
            members.append((f.name, P))
        elif f.kind == "struct":
            members.append((f.name, struct_type(f.type)))
        elif f.kind == "array":
            members.append((f.name, _CTYPES[f.type] * f.elements))
        else:
            members.append((f.name, _CTYPES[f.type]))
    struct: type[ctypes.Structure] = type(owner, (ctypes.Structure,), {"_fields_": members})
    moved = [f.name for f in FIELDS[owner] if getattr(struct, f.name).offset != f.offset]
    if moved or ctypes.sizeof(struct) != SIZES[owner]:
        raise ImportError(
            f"{LIBRARY}: ctypes lays out {owner} unlike the compiler (fields {moved}, size "
            f"{ctypes.sizeof(struct)} vs {SIZES[owner]}); rebuild the library with this "
            "Python's C compiler"
        )
    _STRUCTS[owner] = struct
    return struct


def require_fields(owner: str, expected: Mapping[str, np.dtype | None]) -> None:
    """Refuse, at import, a library whose `owner` struct does not have exactly the fields
    Python declares, with the same element types (None: any)."""
    built = {f.name: ELEMENT_DTYPES.get(f.type) for f in FIELDS.get(owner, [])}
    missing = sorted(set(expected) - set(built))
    extra = sorted(set(built) - set(expected))
    typed = sorted(
        f"{name} ({expected[name]} here, {built[name]} in C)"
        for name in set(expected) & set(built)
        if expected[name] is not None and np.dtype(expected[name]) != built[name]
    )
    if missing or extra or typed:
        raise ImportError(
            f"{LIBRARY} declares {owner} unlike this Python source (missing in C: {missing}; "
            f"unknown to Python: {extra}; other element types: {typed}); rebuild the library "
            "(`pip install -e .`) or update both sides together"
        )


def require_names(what: str, built: tuple[str, ...], expected: tuple[str, ...]) -> None:
    """Refuse, at import, a library whose list `what` differs from Python's."""
    if built != expected:
        raise ImportError(
            f"{LIBRARY} declares {what} {list(built)}; this Python source expects "
            f"{list(expected)}; rebuild the library (`pip install -e .`) or update both sides"
        )


# ---------------------------------------------------------------------------- memory
def allocate(shape: tuple[int, ...], dtype: Any, fill: Any = 0) -> np.ndarray:
    """A new C-contiguous array that C code will point to (every such array comes from here)."""
    return np.full(shape, fill, dtype=dtype)


def address(a: np.ndarray) -> int:
    """The data pointer of a C-contiguous array (checked: the C code assumes it)."""
    if not a.flags.c_contiguous:
        raise NativeError("the compiled rules need C-contiguous arrays")
    return int(a.ctypes.data)


def fill(struct: ctypes.Structure, arrays: Any) -> None:
    """Point every pointer field of `struct` at the array of the same name in `arrays` (a
    mapping, or an object with those attributes), after checking its element type. The
    caller keeps the arrays alive as long as the struct (C holds addresses only)."""
    owner = type(struct).__name__
    for f in FIELDS[owner]:
        if f.kind != "pointer":
            continue
        array = arrays[f.name] if isinstance(arrays, Mapping) else getattr(arrays, f.name)
        if f.type in ELEMENT_DTYPES and array.dtype != ELEMENT_DTYPES[f.type]:
            raise NativeError(f"{owner}.{f.name} is {array.dtype}; C reads {f.type}")
        setattr(struct, f.name, address(array))


def read_only(a: np.ndarray) -> np.ndarray:
    """`a`, made read-only (constants C reads: they cannot be changed from Python)."""
    a.flags.writeable = False
    return a


class Frozen:
    """Attributes that cannot be rebound once `_freeze()` ran: C holds the addresses of the
    arrays they reach, so rebinding one would leave C on old or freed memory. Write into an
    array instead (`obj.name[...] = value`). Names starting with an underscore stay free."""

    _frozen = False

    def _freeze(self) -> None:
        object.__setattr__(self, "_frozen", True)

    def __setattr__(self, name: str, value: Any) -> None:
        if self._frozen and not name.startswith("_"):
            raise AttributeError(
                f"{type(self).__name__}.{name} cannot be rebound: the compiled rules point into "
                f"what it holds; write into its arrays in place (e.g. .{name}[...] = value)"
            )
        object.__setattr__(self, name, value)

    def __delattr__(self, name: str) -> None:
        if self._frozen and not name.startswith("_"):
            raise AttributeError(f"{type(self).__name__}.{name} cannot be deleted")
        object.__delattr__(self, name)
