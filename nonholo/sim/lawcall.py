"""Calling a control law through its address: one compiled single-run code for every law.

A kernel that names a law compiles it, and everything that calls it, once per law: the
lone-root batch kernels need that (LLVM inlines the law into the loops over the batch, which
vectorizes them). A single robot's run (``nonholo.sim.kernel.run_alone``) and the
variable-step solver of the solver-step study do not: they call the law through its address,
so their code is compiled (and cached on disk) once for all laws, and each law adds only a
small C-callable entry point of its own (``law_entry``), also cached.

* ``law_entry(law, gains_class)``: the law as a C function ``void entry(double x, double y,
  double θ, double cos θ, double sin θ, double ξ, double *ref, double *fields, double *out)``
  (ref: one reference row, ``REF_COLUMNS``; fields: a root's ``MAX_FIELDS`` fields, of which
  the law reads the first ``len(gains_class._fields)`` as its gain namedtuple; out: v, ω,
  ξ̇, singular, and 1.0 if the law raised). One per law and gain class, per process.
* ``law_at_address``: a function with a law's signature whose ``ref`` is the address of a
  reference row (``row_address``, or ``stack_copy`` of a row) and whose ``gains`` are
  ``(entry address, fields address)`` (``stack_copy`` of the fields): code written for
  ``law(x, y, θ, cos θ, sin θ, ξ, ref, gains)`` runs any law through it.

The arithmetic is the law's own (compiled with its own options), so results are those of the
law compiled into a kernel.
"""
from __future__ import annotations

import numpy as np
from llvmlite import ir
from numba import carray, cfunc, njit, types
from numba.core import cgutils
from numba.core.dispatcher import Dispatcher
from numba.extending import intrinsic

from nonholo.control.declare import MAX_LAW_FIELDS
from nonholo.references.feedforward import REF_COLUMNS

REF_SIZE = len(REF_COLUMNS)    # a reference row
FIELDS_SIZE = MAX_LAW_FIELDS   # a root's fields (the kernel's ``MAX_FIELDS``)
OUT_SIZE = 5       # v, ω, ξ̇, singular, raised (1.0 if the law raised an exception)
LAW_RAISED = ("the control law raised an exception in a single run, whose compiled code calls it through an "
              "entry that cannot pass exceptions on: call the law from Python, or simulate 4 copies, to see it")
_DOUBLE = types.float64
_POINTER = types.CPointer(_DOUBLE)
ENTRY_SIGNATURE = types.void(*(_DOUBLE,) * 6, _POINTER, _POINTER, _POINTER)


@intrinsic
def call_entry(typingctx, address, x, y, theta, cos_theta, sin_theta, xi, ref, fields):
    """(v, ω, ξ̇, singular, raised) of the law entry at ``address``: the state in registers, ``ref``
    and ``fields`` the addresses (integers) of a reference row and of the root's fields, the
    result through a buffer on the caller's stack (made once, in its entry block, on a cache
    line of its own)."""
    if not all(isinstance(a, types.Integer) for a in (address, ref, fields)):
        return None
    if not all(a == _DOUBLE for a in (x, y, theta, cos_theta, sin_theta, xi)):
        return None
    signature = types.UniTuple(_DOUBLE, OUT_SIZE)(address, x, y, theta, cos_theta, sin_theta, xi, ref, fields)

    def codegen(context, builder, sig, args):
        double = ir.DoubleType()
        pointer = double.as_pointer()
        out = cgutils.alloca_once(builder, ir.ArrayType(double, 8))
        out.align = 64
        out = builder.bitcast(out, pointer)
        entry_type = ir.FunctionType(ir.VoidType(), [double] * 6 + [pointer] * 3)
        entry = builder.inttoptr(args[0], entry_type.as_pointer())
        builder.call(entry, [*args[1:7], builder.inttoptr(args[7], pointer), builder.inttoptr(args[8], pointer), out])
        values = [builder.load(builder.gep(out, [cgutils.int32_t(i)])) for i in range(OUT_SIZE)]
        return context.make_tuple(builder, sig.return_type, values)

    return signature, codegen


@intrinsic
def stack_copy(typingctx, values):
    """The address (an integer) of a copy of the tuple of floats ``values`` in a buffer on
    the caller's stack, valid until the caller returns (one buffer per call site, made in
    the caller's entry block). Use the address only in the function that made it or in
    functions it calls: a compiled function that returns it returns a dangling pointer."""
    if not isinstance(values, types.UniTuple) or values.dtype != _DOUBLE:
        return None

    def codegen(context, builder, sig, args):
        double = ir.DoubleType()
        buffer = cgutils.alloca_once(builder, ir.ArrayType(double, values.count))
        buffer.align = 64
        start = builder.bitcast(buffer, double.as_pointer())
        for i in range(values.count):
            builder.store(builder.extract_value(args[0], i), builder.gep(start, [cgutils.int32_t(i)]))
        return builder.ptrtoint(start, context.get_value_type(types.intp))

    return types.intp(values), codegen


@njit(inline="always", error_model="numpy")
def row_address(rows, row):
    """The address of row ``row`` of the C-contiguous table ``rows`` (as ``call_entry``'s ``ref``)."""
    return rows.ctypes.data + row * rows.strides[0]


@njit(inline="always", error_model="numpy")
def law_at_address(x, y, theta, cos_theta, sin_theta, xi, ref, gains):
    """A law's result through its entry: ``gains`` is ``(entry address, fields address)``
    and ``ref`` the address of a reference row. An exception the law raised is raised here
    as ValueError(LAW_RAISED) (its own message cannot cross the C entry)."""
    address, fields = gains
    v, omega, xi_dot, singular, raised = call_entry(address, x, y, theta, cos_theta, sin_theta, xi, ref, fields)
    if raised != 0.0:
        raise ValueError(LAW_RAISED)
    return v, omega, xi_dot, singular


def stable_cache_identity(dispatcher, _seen=None) -> None:
    """Give ``dispatcher`` and every compiled function its code calls (recursively) a
    deterministic pickling identity.

    numba keys its disk cache of a closure on the pickled closure variables; a law pickles
    *with the functions it calls*, each with a random per-process uuid unless one was set.
    Without this every process would recompile every kernel.
    """
    seen = set() if _seen is None else _seen
    if id(dispatcher) in seen:
        return
    seen.add(id(dispatcher))
    function = dispatcher.py_func
    if getattr(dispatcher, "_MemoMixin__uuid", None) is None:
        dispatcher._set_uuid(f"{function.__module__}.{function.__qualname__}")
    called = [function.__globals__.get(name) for name in function.__code__.co_names]
    called += [cell.cell_contents for cell in function.__closure__ or ()]
    for value in called:
        if isinstance(value, Dispatcher):
            stable_cache_identity(value, seen)


_ENTRIES: dict = {}


def law_entry(law, gains_class):
    """The compiled C entry of ``law`` with gain namedtuple ``gains_class`` (see the module
    docstring), made once per process and cached on disk by numba (its cache key holds the
    law's identity, ``stable_cache_identity``)."""
    key = (law, gains_class)
    if key not in _ENTRIES:
        _ENTRIES[key] = _make_entry(law, gains_class)
    return _ENTRIES[key]


def _make_entry(law, gains_class):
    stable_cache_identity(law)
    n_fields = len(gains_class._fields)

    def entry(x, y, theta, cos_theta, sin_theta, xi, ref_p, fields_p, out_p):
        r = carray(ref_p, REF_SIZE)
        f = carray(fields_p, FIELDS_SIZE)
        out = carray(out_p, OUT_SIZE)
        fields = (f[0], f[1], f[2], f[3], f[4], f[5], f[6], f[7], f[8], f[9])
        ref = (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9])
        gains = gains_class(*fields[:n_fields])
        try:
            out[0], out[1], out[2], out[3] = law(x, y, theta, cos_theta, sin_theta, xi, ref, gains)
            out[4] = 0.0
        except Exception:   # a C entry cannot raise: flag it for law_at_address
            out[0] = out[1] = out[2] = out[3] = np.nan
            out[4] = 1.0

    return cfunc(ENTRY_SIGNATURE, cache=True, error_model="numpy")(entry)
