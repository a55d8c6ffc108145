"""Silverbox: an electronic mass-spring-damper with a cubic (hardening) spring.

Measured data from the nonlinear system identification benchmark of Wigren & Schoukens (the file
``silverbox/SNLS80mV.csv`` of the shared data folder; set ``ARXID_SHARED_DATA`` to the folder that
holds it). ARX(8,8,1) is fitted on the multisine part; :func:`arxid.diagnose` should rank ``y^3``
first, and adding it should cut the free-run error on the arrow-shaped test part by about 80 %.
"""

import os
import sys
from pathlib import Path

import arxid


def main(out: Path) -> None:
    folder = os.environ.get("ARXID_SHARED_DATA")
    path = Path(folder or ".") / "silverbox" / "SNLS80mV.csv"
    if not folder or not path.is_file():
        print(f"skipped: the measured Silverbox data are not here ({path}); set ARXID_SHARED_DATA to the data folder")
        return
    data = arxid.IOData.from_csv(path, output="V2", inputs=["V1"], ts=1 / 610.35)
    est = data[40650:105712]
    offset = {"y": est.y.mean(), "u": est.u.mean()}  # the record's DC offset, removed from every part

    def part(a: int, b: int) -> arxid.IOData:
        d = data[a:b]
        return arxid.IOData(d.y - offset["y"], d.u - offset["u"], d.ts, output_name="V2", input_names=["V1"])

    est, val, test = part(40650, 105712), part(105712, 127400), part(100, 32100)
    model = arxid.arx(est, 8, 8, 1)
    diagnosis = arxid.diagnose(model, est, val)
    print(diagnosis)
    better = diagnosis.apply(0)
    before, after = arxid.compare(model, test), arxid.compare(better, test)
    print(f"\nfree-run RMS on the test part: {before.rms[0]:.4g} V → {after.rms[0]:.4g} V with {diagnosis.top.effect}")
    diagnosis.plot().savefig(out / "suspects.png", dpi=80)
    after.plot().savefig(out / "compare.png", dpi=80)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
