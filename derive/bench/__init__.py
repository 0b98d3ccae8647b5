"""`derive bench` / `make bench`: benchmarks that write a results table.

Speed targets live here, never in unit tests. Every figure is reported against
a reference measured in the same run (ratios), because the machines are shared
and noisy; generated C is compared by callgrind instruction counts where
possible, which are repeatable.

Feature modules contribute benchmarks: each module named in BENCH_MODULES has
``benchmarks() -> dict[str, Callable[[argparse.Namespace], str]]`` returning
markdown sections. Results go to bench/results.md (and stdout). ``derive bench``
(:mod:`derive.cli.bench`) calls :func:`run`.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.resources import CHECKOUT

ROOT = CHECKOUT
BENCH_MODULES: list[str] = ["derive.bench.codegen", "derive.bench.ik", "derive.bench.trajopt", "derive.bench.simulate",
                            "derive.bench.python", "derive.bench.jax_speed", "derive.bench.zoo", "derive.bench.identification",
                            "derive.bench.bundles", "derive.bench.firmware", "derive.bench.large",
                            "derive.bench.pinocchio_cpp", "derive.bench.contacts", "derive.bench.lanes", "derive.bench.throughput",
                            "derive.bench.cuda", "derive.bench.view"]
"""The modules contributing benchmarks, in the order they run and appear in the results."""


class Unavailable(DeriveError):
    """A benchmark this machine cannot run (no GPU, say): named alone, a one-line error and nothing
    written; in a run of all, its section is left out (the results file keeps an earlier one)."""


def registry() -> dict:
    out = {}
    for module in BENCH_MODULES:
        out.update(importlib.import_module(module).benchmarks())
    return out


def run(args, benches: dict | None = None) -> int:
    """Run the benchmarks ``args.names`` (default: all) and write their sections to ``args.out``.

    ``args.quick`` asks for smaller sample sizes. Rerunning some benchmarks into an existing
    results file replaces their sections and keeps the others. ``benches`` (default: every
    module's, :func:`registry`) is what may be run: one module's alone imports no other (a GPU
    machine's image may lack what the others need: ``python -m derive.bench.cuda``).
    """
    if not (ROOT / "generated").is_dir() or not (ROOT / "models.yaml").is_file():
        raise DeriveError(f"bench: measures the project's own models.yaml and generated/, which {ROOT} does not "
                          "hold: run it in a source checkout (`make bench`)")
    benches = registry() if benches is None else benches
    names = args.names or list(benches)
    unknown = [n for n in names if n not in benches]
    if unknown:
        raise DeriveError(f"bench: unknown benchmark {unknown[0]!r} (known: {', '.join(benches)})")
    sections, skipped = [], []
    for name in names:
        check = getattr(benches[name], "check", None)  # what the machine lacks, before any progress line
        try:
            if check is not None:
                check()
            print(f"[bench] {name} ...", flush=True)
            start = time.perf_counter()
            text = benches[name](args)
        except Unavailable as exc:
            if args.names:  # asked for by name: say so, write nothing
                raise DeriveError(f"bench {exc}; {Path(args.out) if args.out else 'bench/results.md'} not written") from None
            print(f"[bench] {name} not run here: {exc}", flush=True)
            skipped.append(name)
            continue
        sections.append(text.rstrip() + "\n")
        print(text, flush=True)
        print(f"[bench] {name} done in {time.perf_counter() - start:.1f} s", flush=True)
    out = Path(args.out) if args.out else ROOT / "bench" / "results.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    header = "# derive benchmark results\n\nWritten by `make bench` (`derive bench`). Ratios are against references measured in the same run.\n\n"
    if (args.names or skipped) and out.exists():  # keep other sections (and those not run here), replace the ones rerun
        old = out.read_text()
        sections = _merge(old, sections)
    write_atomically(out, header + "\n".join(sections), "the benchmark results")
    print(f"[bench] results written to {out}")
    return 0


def _merge(old: str, new_sections: list[str]) -> list[str]:
    def split(text: str) -> dict[str, str]:
        parts, current, title = {}, [], None
        for line in text.splitlines(keepends=True):
            if line.startswith("## "):
                if title:
                    parts[title] = "".join(current)
                title, current = line.strip(), [line]
            elif title:
                current.append(line)
        if title:
            parts[title] = "".join(current)
        return parts

    merged = split(old)
    for sec in new_sections:
        merged.update(split(sec))
    return [v.rstrip() + "\n" for v in merged.values()]

