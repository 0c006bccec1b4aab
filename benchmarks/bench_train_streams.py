"""Two trainings side by side on half the cores each, against each alone on every core.

    python benchmarks/bench_train_streams.py DATASET [--policy-steps 400] [--model-steps 60] [--rounds 2]

``scripts/reproduce_model.sh`` trains the world model (then the camera-less policy) beside the
camera policy, each with half the cores' torch threads. This prints what that rests on, from the
real commands (``orbitmodel train --preset cpu-step5`` and ``orbitmodel train-policy --preset
cpu``, each into a throwaway run folder), in rounds that alternate the configurations:

* each training alone with every core's threads, then alone with half of them: the gain of the
  second half (windows per second, from each run's ``training.json``);
* both at once with half the threads each: the speed of each beside the other, as a ratio to its
  speed alone on half the threads (1.0: they do not slow each other);

and the two runs' training time one after the other on every core against side by side. Set the step counts so that the side-by-side runs last about as long as
each other.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from orbitdata.cli.errors import run_script

os.environ.setdefault("HF_DATASETS_OFFLINE", "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
ORBITMODEL = [sys.executable, "-m", "orbitmodel.cli.app"]


def command(kind: str, dataset: str, out: Path, steps: int, threads: int) -> list[str]:
    if kind == "policy":
        head = ["train-policy", dataset, "--preset", "cpu", "--val-fraction", "0.05"]
    else:
        head = ["train", dataset, "--preset", "cpu-step5"]
    return [*ORBITMODEL, *head, "--out", str(out), "--max-steps", str(steps), "--threads", str(threads)]


def speed(out: Path) -> tuple[float, float]:
    """Windows per second and seconds of the run's (only) training segment."""
    segment = json.loads((out / "training.json").read_text())["segments"][-1]
    return float(segment["windows_per_s"]), float(segment["seconds"])


def train(jobs: list[tuple[str, int, int]], dataset: str, work: Path) -> list[tuple[float, float]]:
    """Run the trainings (kind, steps, threads) at once; each one's windows per second and seconds."""
    outs = [Path(tempfile.mkdtemp(dir=work)) / "run" for _ in jobs]
    procs = [
        subprocess.Popen(command(k, dataset, out, steps, threads), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        for (k, steps, threads), out in zip(jobs, outs)
    ]
    for p in procs:
        _, err = p.communicate()
        if p.returncode:
            raise SystemExit(f"bench_train_streams: a training failed: {err.decode()[-500:]}")
    return [speed(out) for out in outs]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("dataset", help="a 64 px orbitdata dataset (orbitdata generate DIR --image-size 64)")
    parser.add_argument("--policy-steps", type=int, default=400, help="steps of the policy's runs")
    parser.add_argument("--model-steps", type=int, default=60, help="steps of the world model's runs")
    parser.add_argument("--rounds", type=int, default=2, help="rounds of every configuration, alternating")
    args = parser.parse_args()
    cores = os.cpu_count() or 1
    half = max(1, cores // 2)
    steps = {"policy": args.policy_steps, "model": args.model_steps}
    seen: dict[str, list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.rounds):
            for kind in ("policy", "model"):
                seen.setdefault(f"{kind} alone, {cores} threads", []).extend(
                    train([(kind, steps[kind], cores)], args.dataset, Path(tmp))
                )
                seen.setdefault(f"{kind} alone, {half} threads", []).extend(
                    train([(kind, steps[kind], half)], args.dataset, Path(tmp))
                )
            both = train([("policy", steps["policy"], half), ("model", steps["model"], half)], args.dataset, Path(tmp))
            seen.setdefault(f"policy beside model, {half} threads each", []).append(both[0])
            seen.setdefault(f"model beside policy, {half} threads each", []).append(both[1])
    mean = {k: sum(x[0] for x in v) / len(v) for k, v in seen.items()}  # windows per second
    secs = {k: sum(x[1] for x in v) / len(v) for k, v in seen.items()}
    print(f"{cores} cores; windows per second, each round then the mean")
    for k, v in seen.items():
        print(f"  {k:42s} " + "  ".join(f"{x[0]:7.2f}" for x in v) + f"   mean {mean[k]:7.2f}")
    for kind, other in (("policy", "model"), ("model", "policy")):
        gain = mean[f"{kind} alone, {cores} threads"] / mean[f"{kind} alone, {half} threads"]
        beside = mean[f"{kind} beside {other}, {half} threads each"] / mean[f"{kind} alone, {half} threads"]
        print(
            f"{kind}: {cores} threads against {half}: {gain:.2f}x; beside the other against alone on {half}: {beside:.2f}x"
        )
    # the same two runs one after the other on every core, against side by side (mean seconds)
    after = secs[f"policy alone, {cores} threads"] + secs[f"model alone, {cores} threads"]
    side = max(secs[f"policy beside model, {half} threads each"], secs[f"model beside policy, {half} threads each"])
    print(
        f"both runs: {after:.1f} s one after the other on {cores} threads, {side:.1f} s side by side: {after / side:.2f}x"
    )


if __name__ == "__main__":
    run_script(main)
