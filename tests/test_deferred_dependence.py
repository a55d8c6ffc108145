"""The dependence test of a diagnosis runs when first read: a ladder runs its last diagnosis's test
(what it leaves unexplained), and the diagnoses it steps past run theirs only if asked."""

import sys
from pathlib import Path

import arxid
from arxid.diagnosis import suspects
from arxid.diagnosis.ladder import Ladder
from arxid.diagnosis.nonlinearity import nonlinear_dependence

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benches"))
from analyse_scale import make_record  # noqa: E402  (the battery-scaled plant of the benchmark)


def test_the_ladder_runs_its_last_test_and_the_others_on_first_read(monkeypatch):
    calls = []

    def counted(model, data, alpha):
        calls.append(model.structure_name())
        return nonlinear_dependence(model, data, alpha)

    monkeypatch.setattr(suspects, "nonlinear_dependence", counted)
    est, val = make_record(20000, 11), make_record(20000, 21)
    ladder = Ladder.run(arxid.arx(est, 2, 2, 1), est, val, max_steps=2)
    assert len(ladder.diagnoses) >= 2  # the battery is found, then nothing more
    last = ladder.diagnoses[-1].model.structure_name()
    assert calls == [last]
    first = ladder.diagnoses[0]
    got = first.nonlinear_dependence
    assert calls == [last, first.model.structure_name()]
    want = nonlinear_dependence(first.model, est, first.alpha)
    assert [d.to_dict() for d in got] == [d.to_dict() for d in want]
    assert first.nonlinear_dependence is got and len(calls) == 2  # read once, kept
