"""Times mogen's DNO step against the PyTorch mirror, interleaved, and prints a markdown table.

    python compare.py --mogen target/release/mogen --prior fixtures/model/prior.safetensors

Each round runs `mogen bench prior --json` (2 threads, and 1 thread for the scaling column)
and `dno_step.py` (2 threads) back to back, reversing the order every round; ratios are taken
per round and the medians printed, so a load change on the machine hits both sides alike.
The parity check runs first: the table is only printed when both compute the same step.

`--simd avx2` runs both sides on AVX2/FMA even where the CPU has AVX-512: mogen with
`MOGEN_SIMD=avx2`, PyTorch with `ATEN_CPU_CAPABILITY=avx2`, `MKL_ENABLE_INSTRUCTIONS=AVX2` and
`ONEDNN_MAX_CPU_ISA=AVX2`; the table names the set each side reports. The GFLOP/s are set
against mogen's sgemm rate on a large square product (`mogen bench prior --sgemm`) on the same
set, for 1 and 2 threads.
"""

import argparse
import json
import os
import statistics
import struct
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


# Environment that keeps each side on AVX2/FMA on a CPU with AVX-512.
AVX2_ENV = {
    "mogen": {"MOGEN_SIMD": "avx2"},
    "torch": {"ATEN_CPU_CAPABILITY": "avx2", "MKL_ENABLE_INSTRUCTIONS": "AVX2", "ONEDNN_MAX_CPU_ISA": "AVX2"},
}


def lines_json(cmd, env):
    out = subprocess.run(cmd, check=True, capture_output=True, text=True, env=env).stdout
    return [json.loads(line) for line in out.splitlines() if line.startswith("{")]


def run_json(cmd, env):
    return {r["batch"]: r for r in lines_json(cmd, env)}


def prior_config(path):
    """The `mdm_config` in a prior file's safetensors metadata."""
    with open(path, "rb") as f:
        n = struct.unpack("<Q", f.read(8))[0]
        return json.loads(json.loads(f.read(n))["__metadata__"]["mdm_config"])


def step_gflop(batch, d, ff, layers, frames=100, feats=263, k=10):
    """Analytic GFLOP of one step (K passes forward, input gradient only backward): linear
    layers count twice (forward, dX), attention three times (forward, both operands)."""
    s = frames + 1
    lin = 2 * batch * s * layers * d * (4 * d + 2 * ff) + 4 * batch * frames * feats * d
    attn = 4 * batch * s * s * d * layers
    return k * (2 * lin + 3 * attn) / 1e9


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--mogen", required=True)
    ap.add_argument("--prior", required=True)
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--batches", default="1,2,8")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--simd", choices=["native", "avx2"], default="native",
                    help="instruction set of both sides (avx2: no AVX-512 on either)")
    ap.add_argument("--sgemm", type=int, default=2048, help="side of the square product for the sgemm peak")
    args = ap.parse_args()
    envs = {side: dict(os.environ, **(AVX2_ENV[side] if args.simd == "avx2" else {})) for side in ("mogen", "torch")}
    mirror = [args.python, os.path.join(HERE, "dno_step.py"), "--prior", args.prior]
    cfg = prior_config(args.prior)
    dump = tempfile.mkdtemp()
    subprocess.run([args.mogen, "bench", "prior", "--prior", args.prior, "--batches", "1", "--reps", "1", "--dump", dump],
                   check=True, capture_output=True, env=envs["mogen"])
    subprocess.run(mirror + ["--check", dump], check=True, env=envs["torch"])
    peak = {}
    for threads in (1, 2):
        probe = lines_json([args.mogen, "bench", "prior", "--prior", args.prior, "--json", "--threads", str(threads),
                            "--sgemm", str(args.sgemm)], envs["mogen"])[0]
        peak[threads] = probe["gflops"]
    print(f"sgemm {args.sgemm}² on mogen's {probe['simd']} kernels: {peak[1]:.0f} GFLOP/s on 1 thread, "
          f"{peak[2]:.0f} on 2.", file=sys.stderr, flush=True)
    common = ["--batches", args.batches, "--reps", str(args.reps)]
    ours = [args.mogen, "bench", "prior", "--prior", args.prior, "--json"] + common
    theirs = mirror + ["--threads", "2", "--text", os.path.join(dump, "text.npy")] + common
    batches = [int(b) for b in args.batches.split(",")]
    rows = {b: {"ours": [], "one": [], "torch": [], "ratio": [], "rss": 0.0, "torch_rss": 0.0} for b in batches}
    sets = {}
    for r in range(args.rounds):
        order = [("ours", ours + ["--threads", "2"], "mogen"), ("one", ours + ["--threads", "1"], "mogen"),
                 ("torch", theirs, "torch")]
        results = {name: run_json(cmd, envs[side]) for name, cmd, side in (order if r % 2 == 0 else order[::-1])}
        sets = {"mogen": results["ours"][batches[0]]["simd"], "torch": results["torch"][batches[0]]["cpu_capability"]}
        for b in batches:
            row = rows[b]
            for name in ("ours", "one", "torch"):
                row[name].append(results[name][b]["dno_step_s"])
            row["ratio"].append(results["ours"][b]["dno_step_s"] / results["torch"][b]["dno_step_s"])
            row["rss"] = max(row["rss"], results["ours"][b]["peak_rss_mib"])
            row["torch_rss"] = max(row["torch_rss"], results["torch"][b]["peak_rss_mib"])
        print(f"round {r + 1}/{args.rounds} done", file=sys.stderr, flush=True)
    load = os.getloadavg()
    print(f"Medians of {args.rounds} interleaved rounds ({args.reps} steps each after a warm-up); "
          f"load average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f}. "
          f"Instruction sets: mogen {sets['mogen']}, PyTorch {sets['torch']}. "
          f"sgemm {args.sgemm}² on mogen's kernels: {peak[1]:.0f} GFLOP/s (1 thread), {peak[2]:.0f} (2 threads).\n")
    print("| batch | GFLOP/step | mogen, 2 threads (s) | PyTorch, 2 threads (s) | ratio (per-round range) | mogen GFLOP/s (% of sgemm) | PyTorch GFLOP/s (% of sgemm) | mogen, 1 thread (s) (% of sgemm) | 1 → 2 threads | peak RSS MiB mogen / PyTorch |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for b in batches:
        row = rows[b]
        ours_s, torch_s, one_s = (statistics.median(row[n]) for n in ("ours", "torch", "one"))
        gf = step_gflop(b, cfg["latent_dim"], cfg["ff_size"], cfg["num_layers"])
        share = lambda s, threads: f"{gf / s:.0f} ({100 * gf / s / peak[threads]:.0f} %)"
        print(f"| {b} | {gf:.1f} | {ours_s:.4f} | {torch_s:.4f} | {statistics.median(row['ratio']):.2f} "
              f"({min(row['ratio']):.2f}–{max(row['ratio']):.2f}) | {share(ours_s, 2)} | {share(torch_s, 2)} | "
              f"{one_s:.4f} ({100 * gf / one_s / peak[1]:.0f} %) | {one_s / ours_s:.2f}× | "
              f"{row['rss']:.0f} / {row['torch_rss']:.0f} |")


if __name__ == "__main__":
    main()
