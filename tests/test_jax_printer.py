"""The JAX printer's choice of what XLA computes once (derive.codegen.backends.jax.printer): a shared
temporary where the arithmetic XLA would repeat, (uses - 1) x its inlined tree, reaches KEEP_WASTE;
an input element read by at least KEEP_INPUT_USES operations; the functions evaluated in blocks. On
hand-made programs (no jax needed)."""

from __future__ import annotations

from derive.codegen.backends.jax.printer import (BLOCK, KEEP_INPUT_USES, KEEP_WASTE, MIN_STORED, STORED_PER_ENTRY,
                                                  JaxPrinter)
from derive.codegen.program import Instr, Program


def program() -> Program:
    x = lambda i: ("in", 0, i)  # noqa: E731
    t = lambda k: ("t", k)  # noqa: E731
    body = [Instr("mul", (x(0), x(1))),   # t0: tree 1, 3 uses: repeats 2
            Instr("add", (t(0), x(0))),   # t1: tree 2, 1 use
            Instr("mul", (t(1), t(0))),   # t2: tree 4, 2 uses: repeats 4
            Instr("sub", (t(2), t(0))),   # t3: tree 6, 3 uses: repeats 12, kept
            Instr("mul", (t(3), t(2))),   # t4: tree 5 (t3 kept), 1 use
            Instr("sin", (t(3),))]        # t5: tree 20, 2 uses: repeats 20, kept
    results = [(0, 0, t(3)), (0, 1, t(4)), (0, 2, t(5)), (0, 3, t(5)), (0, 4, x(0))]
    return Program([("x", (3, 1))], [("y", (5, 1))], body, results)


def test_kept_temporaries_and_inputs():
    assert KEEP_WASTE == 8 and KEEP_INPUT_USES == 3  # the figures the program above is built around
    printer = JaxPrinter(["x"])
    prog = program()
    assert printer.kept(prog) == {3, 5}
    assert printer.kept_inputs(prog) == {"x": (0,)}  # x0: t0, t1 and the output; x1 once, x2 never
    body = dict(printer.body(prog))
    assert body["t3"] == "_keep(t2 - t0, one)" and body["t5"] == "_keep(jnp.sin(t3), one)"
    assert body["t2"] == "t1 * t0" and body["t0"] == "x_[0] * x_[1]"


def stores(kept: int, entries: int) -> Program:
    """kept temporaries (sin(x0), each read twice by a product) and one kept input row (x0, read by each
    sin), entries output entries (the products, then x1)."""
    x0, x1 = ("in", 0, 0), ("in", 0, 1)
    body = [Instr("sin", (x0,)) for _ in range(kept)] + [Instr("mul", (("t", k), ("t", k))) for k in range(kept)]
    results = [(0, i, ("t", kept + i) if i < kept else x1) for i in range(entries)]
    return Program([("x", (2, 1))], [("y", (entries, 1))], body, results)


def test_blocked_functions():
    """Blocked (BLOCK states per block) where the stored values, kept temporaries and kept input rows,
    are at least MIN_STORED and STORED_PER_ENTRY per output entry; otherwise None."""
    assert (MIN_STORED, STORED_PER_ENTRY) == (64, 2)  # the figures the programs below are built around
    printer = JaxPrinter(["x"])
    prog = stores(63, 32)
    assert len(printer.kept(prog)) == 63 and printer.kept_inputs(prog) == {"x": (0,)}
    assert printer.block(prog) == BLOCK  # 64 stored, 2 per entry
    assert printer.block(stores(63, 33)) is None  # 64 stored for 33 entries
    assert printer.block(stores(62, 20)) is None  # 63 stored
    assert printer.block(program()) is None
