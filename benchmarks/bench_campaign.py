"""Benchmark: campaign throughput and the overhead of the trial store and of Dask (issue 14).

On the 4-robot example with the literature's noise (``examples/four-robots.toml``), one nominal plan:

- **bare trials**: ``run_trial`` in a loop, no store: the mean wall time of one closed-loop trial, the
  unit every overhead is measured against;
- **campaigns**: ``run_campaign`` into a file store (``trials.sqlite``, WAL, one commit per trial) with
  1, 2 and all local worker processes, and on a Dask LocalCluster (all cores; cluster start-up reported
  apart): trials per second;
- **store overhead**: the time of one committed trial row (``TrialStore.record``, measured over many
  commits) relative to the mean trial (target < 5 %);
- **Dask overhead**: the round trip of a task carrying a campaign-sized context and a trial-sized
  result through the LocalCluster (submit, run, as_completed, result), per task, relative to the mean
  trial (target < 5 %).

Throughput figures depend on what else runs on the machine: the script prints the load average so a
reader can judge. Run: ``nice python benchmarks/bench_campaign.py [--trials N]`` (needs the [dask] extra
for the Dask rows).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from stressbots import montecarlo as mc
from stressbots.campaign import outcome_row, run_campaign
from stressbots.scenario import load
from stressbots.store import TrialStore

ROOT = Path(__file__).resolve().parents[1]


def _noop(ctx, task):  # noqa: ARG001 - ctx is shipped like a real trial's context, unused
    """A Dask task that does no work but carries the same context and returns a trial-sized result."""
    from stressbots.montecarlo import TrialOutcome

    return TrialOutcome(task[2], task[3], 1.0, True, None, 1.0, 1.0, 1.0, 1.0, 1, 4, 4), "w", "code"


def bare_trials(scn, plan, seeds) -> list[float]:
    assemble = mc.default_assemble()
    return [mc.run_trial(scn, plan, k, s, assemble).wall_s for k, s in enumerate(seeds)]


def campaign_rate(camp, workers: int | None, dask: str | None = None) -> tuple[float, float]:
    """(trials per second, wall s) of a fresh campaign into a file store."""
    with tempfile.TemporaryDirectory() as d, TrialStore.open(Path(d) / "trials.sqlite", {"bench": 1}) as store:
        t0 = time.perf_counter()
        info = run_campaign(camp, store, workers=workers, dask=dask)
        wall = time.perf_counter() - t0
        assert len(store) == camp.total and info.ran == camp.total
    return camp.total / wall, wall


def store_commit_s(camp, n: int = 2000) -> float:
    """Mean seconds per committed trial row (WAL, synchronous=NORMAL, one transaction each)."""
    out = mc.run_trial(camp.cells[0].scenario, camp.cells[0].plan, 0, camp.seeds[0], camp.assemble)
    with tempfile.TemporaryDirectory() as d, TrialStore.open(Path(d) / "trials.sqlite", {"bench": 1}) as store:
        t0 = time.perf_counter()
        for i in range(n):
            row = outcome_row(out, n)
            row["trial"] = i
            store.record(row)
        return (time.perf_counter() - t0) / n


def dask_overhead(camp, n: int = 200) -> tuple[float, float]:
    """(start-up s, seconds per no-op task) of a LocalCluster of every core, tasks through as_completed."""
    from distributed import as_completed

    from stressbots.campaign import dask_client

    t0 = time.perf_counter()
    with dask_client("local", None) as client:
        startup = time.perf_counter() - t0
        ctx = client.scatter(camp, broadcast=True, hash=False)
        tasks = [(i, 0, i, i) for i in range(n)]
        t1 = time.perf_counter()
        futs = [client.submit(_noop, ctx, t, pure=False) for t in tasks]
        for f in as_completed(futs):
            f.result()
        # conservative: the no-op tasks' wall time times the workers, as if every worker were busy with it
        per = (time.perf_counter() - t1) * len(client.scheduler_info()["workers"]) / n
    return startup, per


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=12, help="trials per configuration")
    args = ap.parse_args()
    cores = os.cpu_count() or 1
    print(f"load average {os.getloadavg()[0]:.1f} on {cores} cores (figures are under this contention)")
    scn = load(ROOT / "examples" / "four-robots.toml")
    plan = mc.default_planner()(scn)
    camp = mc.montecarlo_campaign(scn, args.trials, 1, (1.0,), assemble=mc.default_assemble(), plan=plan)
    walls = bare_trials(scn, plan, camp.seeds)
    trial_s = sum(walls) / len(walls)
    print(f"bare 4-robot trial: mean {trial_s:.3f} s wall ({len(walls)} trials, {1 / trial_s:.2f} trials/s in one process)")
    for w in sorted({1, 2, cores}):
        rate, wall = campaign_rate(camp, w)
        print(f"campaign, {w} local worker{'s' if w > 1 else ''}: {rate:.2f} trials/s ({wall:.1f} s for {camp.total})")
    commit = store_commit_s(camp)
    print(f"store: {1e3 * commit:.3f} ms per committed trial = {100 * commit / trial_s:.3f} % of a 4-robot trial")
    try:
        import distributed  # noqa: F401
    except ImportError:
        print("dask: not installed (pip install 'stressbots[dask]'); skipped")
        return
    rate, wall = campaign_rate(camp, None, dask="local")
    print(f"campaign, Dask LocalCluster ({cores} workers): {rate:.2f} trials/s ({wall:.1f} s for {camp.total}, cluster start-up included)")
    startup, per = dask_overhead(camp)
    print(f"dask: cluster start-up {startup:.1f} s (once per campaign); {1e3 * per:.2f} ms per task round trip "
          f"= {100 * per / trial_s:.2f} % of a 4-robot trial")


if __name__ == "__main__":
    main()
