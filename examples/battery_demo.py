"""The hidden battery effect (what ``arxid demo`` tells).

A simulated quadrotor climbs and hovers for 20 s while its battery sags; the vertical
acceleration answers the thrust command with a gain that is proportional to the battery voltage.
:func:`arxid.analyse` sweeps the default grid, chooses a structure, checks its residuals, ranks
the physical effects the model is missing and adds them one at a time (the ladder). It should name
the thrust command times the battery voltage, and the validation error should fall.
"""

import io
import sys
from pathlib import Path

from arxid.analysis.demo import run_demo


def main(out: Path) -> None:
    story = io.StringIO()
    result = run_demo(output=out / "report.html", seed=0, stream=story)
    print(story.getvalue().replace(str(out / "report.html"), "report.html"))
    (out / "report.html").unlink()  # the gallery shows the figures; `arxid demo` writes the report
    a = result.analysis
    a.diagnosis.plot().savefig(out / "suspects.png", dpi=80)
    a.ladder.plot().savefig(out / "ladder.png", dpi=80)


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "."))
