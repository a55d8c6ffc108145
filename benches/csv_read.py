"""How fast ``IOData.from_csv`` reads a large log, and how much memory it needs.

A CSV of 200,000 rows × 5 columns (time, output, two inputs, battery voltage; ``%.9g``, about
11 MB) is read by ``IOData.from_csv`` with a time column (the Rust reader: lines split and parsed
on every core, the ``csv`` crate for quoted records), once as it is and once with CRLF line endings
and one quoted row. The reference
is ``pandas.read_csv`` alone on the same file, measured in the same run. Each reader runs in a
fresh process: the time is the best of five reads after one warm-up; the peak memory is the growth
of the process' peak resident set during one read, compared with the size of the five float64
columns (8 MB).

Targets (issue 26): at most 1.5× the time of ``pandas.read_csv`` alone; (issue 16) peak memory
under 3× the array size.

    python benches/csv_read.py [--rows 200000]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

# One measurement, run in a child process so that imports and earlier reads do not count.
CHILD = r"""
import json, resource, sys, time
mode, path = sys.argv[1], sys.argv[2]
import numpy as np
import arxid
import arxid.data.csvio
def read():
    if mode == "pandas.read_csv alone":
        import pandas as pd
        return pd.read_csv(path)
    return arxid.IOData.from_csv(path, output="y", inputs=["u1", "u2"], extra=["vbat"], time="time")

def rss_kib():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * resource.getpagesize() // 1024

small = path + ".small.csv"
with open(path) as src, open(small, "w") as dst:
    dst.writelines(line for _, line in zip(range(100), src))
path, big = small, path
read()  # warm-up: imports, first-call costs
path = big
before = rss_kib()
data = read()
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
del data
times = []
for _ in range(5):
    t0 = time.perf_counter(); read(); times.append(time.perf_counter() - t0)
print(json.dumps({"seconds": min(times), "peak_kib": peak}))
"""


def _measure(mode: str, path: Path) -> dict:
    if mode == "arxid, CRLF + quoted row":
        quoted = path.with_name("quoted.csv")
        header, first, rest = path.read_text().split("\n", 2)
        cells = '","'.join(first.split(","))
        quoted.write_bytes(f'{header}\n"{cells}"\n{rest}'.replace("\n", "\r\n").encode())
        path = quoted
    out = subprocess.run([sys.executable, "-c", CHILD, mode, str(path)], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=200_000)
    rows = parser.parse_args().rows
    rng = np.random.default_rng(0)
    table = np.column_stack(
        [np.arange(rows) * 0.002, rng.standard_normal(rows), rng.standard_normal(rows), rng.random(rows),
         4.2 - 0.5 * np.arange(rows) / rows]
    )  # fmt: skip
    array_mib = table.nbytes / 2**20
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "flight.csv"
        np.savetxt(path, table, fmt="%.9g", delimiter=",", header="time,y,u1,u2,vbat", comments="")
        print(
            f"{rows:,} rows × 5 columns, {path.stat().st_size / 2**20:.1f} MiB of CSV, {array_mib:.1f} MiB as float64"
        )
        print(f"{'reader':<24}{'time':>10}{'vs pandas alone':>17}{'peak memory':>14}{'× array':>9}")
        results = {}
        for mode in ("pandas.read_csv alone", "arxid", "arxid, CRLF + quoted row"):
            r = results[mode] = _measure(mode, path)
            ratio = r["seconds"] / results["pandas.read_csv alone"]["seconds"]
            peak = r["peak_kib"] / 1024
            print(f"{mode:<24}{r['seconds']:>9.3f}s{ratio:>16.2f}×{peak:>10.1f} MiB{peak / array_mib:>8.2f}×")
    fast, pandas = results["arxid"], results["pandas.read_csv alone"]
    ok_time = fast["seconds"] <= 1.5 * pandas["seconds"]
    ok_memory = fast["peak_kib"] / 1024 < 3 * array_mib
    verdict = {True: "met", False: "MISSED"}
    print(f"target: <= 1.5× pandas.read_csv {verdict[ok_time]}; peak memory < 3× the array {verdict[ok_memory]}")


if __name__ == "__main__":
    main()
