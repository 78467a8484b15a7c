"""An onset the trigger found to be no blow where the gap loader has no whole window before it to
judge again (the record's first samples) stays out of the impacts, said in a line (issue 17,
modal benchmark seed 555000: an ambient tone fired the trigger 10 ms into the record; kept, it
was a fifth impact at the tone's level, and the homogeneity check read "decrement changes by
+36 % per doubling of the blow" where the right answer was the tone)."""

from __future__ import annotations

from ramdaq.daq.commands import gap_bench
from ramdaq.daq.gap_trial import load_trial
from ramdaq.daq.record import record
from ramdaq.drivers.array_device import ArrayDevice


def test_a_no_blow_onset_at_the_records_start_is_no_impact(tmp_path):
    sc = next(s for s in gap_bench.scenarios(6, "benchmark", ("ambient_tone",), 0.25, "modal", 4)
              if s["seed"] == 555000)
    gen = gap_bench._generate_modal(sc)     # the modal family: nothing shared with the loader
    path = tmp_path / "tone.mcap"
    record(ArrayDevice(gen["counts"], gen["scale"], gen["fs_hz"], gages=gen["gages"],
                       rig_toml=gen["rig"].text, extra={"medium": sc["medium"], "adc_bits": gen["adc_bits"]}),
           path, readout=False, overwrite=True)
    said: list[str] = []
    lt = load_trial(path, progress=said.append)
    assert len(lt.onsets_s) == gen["n_impacts"] == 4, lt.onsets_s
    assert lt.onsets_s[0] > 1.0                   # the blows, not the start
    line = [s for s in said if "is no blow" in s]
    assert len(line) == 1 and "at 0.011 s" in line[0] and "the trigger's words: no blow" in line[0], said
