#!/usr/bin/env python3
"""Speed of `mogen` against a pinned earlier commit, on one machine, in one run.

Absolute seconds differ by 2x between the machines this project runs on, so the evidence is the
ratio of the two binaries' times measured side by side: both are built here (the earlier commit
in a git worktree of its own), then every task is run with both, interleaved (base, current,
current, base, ...), for several rounds. For each task the script prints the median wall time of
each binary, their ratio (base / current: how many times faster the current one is), and each
run's constraint and motion figures from its report.json side by side, so that a faster run that
meets fewer constraints or skates more is seen at once.

    python3 benches/speed/compare.py --base 495280a --rounds 3
    python3 benches/speed/compare.py --base 495280a --task 'main="walk 3 m forwards" --method dno' \
        --task 'task2=run fixtures/tasks/rgdno_task2_low_barrier.json --method rg-dno -n 2'

A task is NAME=ARGS (the arguments of `mogen`, split as a shell splits words, so a task in words
is quoted; `-o` is added);
the default tasks are the README's main command, Task 2 with RG-DNO (2 samples) and Task 1 with
DNO. `--base-bin` / `--current-bin` take binaries already built instead of building them.
Only the Python standard library is used; the builds need cargo.
"""

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

DEFAULT_TASKS = [
    'main="walk forwards through a 0.4 m wide gap and stop 5 m ahead"',
    "task2=run fixtures/tasks/rgdno_task2_low_barrier.json --method rg-dno -n 2",
    "task1-dno=run fixtures/tasks/rgdno_task1_narrow_gap.json --method dno",
]

# Figures read from report.json, with the key path and how they print.
FIGURES = [
    ("met", ["success_rate"], "{:.0%}"),
    ("error", ["constraint_error"], "{:.5f}"),
    ("skate", ["foot_skate_ratio"], "{:.3f}"),
    ("max acc", ["max_acceleration"], "{:.4f}"),
]


def parse_task(text):
    """NAME=ARGS: a name for the table and the arguments of `mogen`, split as a shell splits
    words (a task in words is quoted: `main="walk 3 m" --method dno`)."""
    name, sep, args = text.partition("=")
    if not sep or not name or not args.strip():
        sys.exit(f"--task {text!r}: expected NAME=ARGS")
    return name, shlex.split(args)


def build(commit, target_dir):
    """Builds `mogen` at `commit` (None: the working tree) and returns the binary's path."""
    env = dict(os.environ, CARGO_TARGET_DIR=str(target_dir))
    if commit is None:
        source = ROOT
    else:
        source = Path(tempfile.mkdtemp(prefix="mogen-base-"))
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(source), commit], check=True)
    print(f"building {commit or 'the working tree'} in {target_dir}", file=sys.stderr)
    try:
        subprocess.run(["cargo", "build", "--release", "-p", "agent"], cwd=source, env=env, check=True)
    finally:
        if commit is not None:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(source)], check=False)
    return Path(target_dir) / "release" / "mogen"


def run_once(binary, args, out):
    """Runs `binary args -o out` from the repository root; returns (wall seconds, report)."""
    start = time.perf_counter()
    done = subprocess.run([str(binary), *args, "-o", str(out)], cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{binary} {shlex.join(args)} failed:\n{done.stderr[-4000:]}")
    report = json.loads((Path(out) / "report.json").read_text())
    return wall, report


def figure(report, path):
    value = report
    for key in path:
        value = value.get(key) if isinstance(value, dict) else None
    return value


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", help="the earlier commit to build and compare with")
    parser.add_argument("--base-bin", type=Path, help="a binary of the earlier commit, already built")
    parser.add_argument("--current-bin", type=Path, help="a binary of the working tree, already built")
    parser.add_argument("--task", action="append", help="NAME=ARGS of mogen (repeatable)")
    parser.add_argument("--rounds", type=int, default=3, help="runs of each task with each binary")
    parser.add_argument(
        "--current-extra",
        default="",
        help="arguments added to the current binary's runs only (a new option against the base's default)",
    )
    parser.add_argument("--work", type=Path, help="folder for builds and outputs (default: a new temporary one)")
    args = parser.parse_args()
    if args.base_bin is None and args.base is None:
        parser.error("give --base COMMIT or --base-bin FILE")
    if args.rounds < 1:
        parser.error("--rounds must be at least 1")
    work = args.work or Path(tempfile.mkdtemp(prefix="mogen-speed-"))
    base = args.base_bin or build(args.base, work / "target-base")
    current = args.current_bin or build(None, work / "target-current")
    tasks = [parse_task(t) for t in (args.task or DEFAULT_TASKS)]
    extra = {"base": [], "current": shlex.split(args.current_extra)}

    results = {}
    for r in range(args.rounds):
        for name, task_args in tasks:
            # Alternate which binary goes first, so that a machine that drifts within a round
            # weighs on both alike.
            order = [("base", base), ("current", current)]
            if r % 2:
                order.reverse()
            for label, binary in order:
                out = work / "out" / f"{name}-{label}-{r}"
                wall, report = run_once(binary, task_args + extra[label], out)
                results.setdefault(name, {}).setdefault(label, []).append((wall, report))
                print(f"round {r + 1}: {name} {label} {wall:.1f} s", file=sys.stderr)

    with_extra = f" with {args.current_extra}" if args.current_extra else ""
    print(f"mogen speed: base {args.base or base} against the working tree{with_extra}; {args.rounds} round(s), interleaved\n")
    header = "| task | base median (s) | current median (s) | base / current |"
    header += "".join(f" {f[0]} base → current |" for f in FIGURES)
    print(header)
    print("|" + "---|" * (4 + len(FIGURES)))
    for name, _ in tasks:
        runs = results[name]
        medians = {label: statistics.median(w for w, _ in runs[label]) for label in ("base", "current")}
        row = f"| {name} | {medians['base']:.1f} | {medians['current']:.1f} | {medians['base'] / medians['current']:.2f} |"
        for _, path, fmt in FIGURES:

            def shown(label):
                values = [figure(rep, path) for _, rep in runs[label]]
                return ", ".join("–" if v is None else fmt.format(v) for v in values)

            row += f" {shown('base')} → {shown('current')} |"
        print(row)
    print(f"\noutputs in {work / 'out'}")


if __name__ == "__main__":
    main()
