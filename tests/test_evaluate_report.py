"""Report plumbing: the tuning set is disjoint from what is reported; README splicing."""

import numpy as np

from companion.mission import load_mission
from gcs_tools.evaluate import report, tuning


def test_tuning_set_is_the_default_city_with_other_checked_profiles():
    reported = load_mission("default")
    tuned = tuning.load(tuning.TUNING_MISSION)
    assert tuple(range(len(tuned.profiles))) == tuning.profiles()
    assert np.array_equal(tuned.world.rects_m, reported.world.rects_m)
    ends = {tuple(p.start_ne_m) for p in reported.profiles} | {tuple(p.goal_ne_m) for p in reported.profiles}
    for p in tuned.profiles:
        assert tuple(p.start_ne_m) not in ends and tuple(p.goal_ne_m) not in ends
    t = report.tuning_set()
    assert not t.overlap("default", range(10), range(50))
    assert t.overlap("default", range(10), [3, 1004])
    assert t.overlap(tuning.TUNING_MISSION, [0], [0])


def test_readme_block_is_replaced_in_place(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("# x\n\nintro\n")
    report.splice_readme(readme, "results", "table one")
    report.splice_readme(readme, "seeds", "table two")
    report.splice_readme(readme, "results", "table three\n")
    text = readme.read_text()
    assert text.count("<!-- results:results -->") == 1 and "table one" not in text
    assert text.index("table three") < text.index("table two") and text.startswith("# x\n\nintro\n")


def test_ranges():
    assert report._ranges([0, 1, 2, 5, 7, 8]) == "0–2, 5, 7–8"
    assert report._ranges([3]) == "3"
