"""tools/experiment_tracking.py without ROS playback: the straight-part selection on hand-counted keyframes, and the
kitti00_far variants (what each imports and how each starts)."""

from __future__ import annotations

import experiment_tracking as et
import numpy as np


def test_straight_parts_leave_out_each_turn_and_its_margin():
    keyframes = np.arange(770, 801)
    # The turn 777-791 widened by 3 keyframes: 774-794 out, 770-773 and 795-800 in.
    expected = (keyframes < 774) | (keyframes > 794)
    np.testing.assert_array_equal(et.straight(keyframes, turns=((777, 791),), margin=3), expected)
    np.testing.assert_array_equal(
        et.straight(keyframes, turns=((777, 791),), margin=0), (keyframes < 777) | (keyframes > 791)
    )


def test_straight_parts_of_the_whole_data_set():
    keyframes = np.concatenate([np.arange(696, 948), np.arange(1042, 1351)])
    kept = et.straight(keyframes)
    # Turn lengths 15, 7, 14, 6 and 8 keyframes, each widened by 2 x 3: 50 + 30 = 80 keyframes out.
    assert kept.sum() == len(keyframes) - 80
    assert not kept[keyframes == 774].any() and kept[keyframes == 773].all()
    assert not kept[keyframes == 1234].any() and kept[keyframes == 1235].all()


def test_each_stretch_runs_five_variants_on_two_imports():
    for name, (first, last, gap_at) in et.STRETCHES.items():
        stem = f"kitti_{name}"
        variants = {v: et.VARIANTS[v] for v in et.SETS["real"] if v.startswith(stem + "_") or v == stem}
        assert len(variants) == 5
        assert {v.scenario for v in variants.values()} == {stem, f"{stem}_drop20_gap8"}
        base = et.VARIANTS[stem].command
        assert (
            base[0] == "import"
            and base[base.index("--first") + 1 : base.index("--last") + 2] == (str(first), "--last", str(last))
            and base[-2:] == ("--map-every", "3")
        )
        thinned = et.VARIANTS[f"{stem}_drop20_gap8"].command
        assert thinned[: len(base)] == base and thinned[len(base) :] == (
            "--drop-fraction",
            "0.2",
            "--seed",
            "0",
            "--gap",
            f"{gap_at:g}",
            "8",
        )
        for v in variants.values():
            assert v.experiment[:2] == ("--preset", "urban")
        assert et.VARIANTS[f"{stem}_offset20_90"].experiment[2:] == ("--start-offset", "20", "90")
        assert et.VARIANTS[f"{stem}_hint20"].experiment[2:] == ("--start", "hint", "--hint-sigma", "20")
        assert et.VARIANTS[f"{stem}_none"].experiment[2:] == ("--start", "none")
    assert not any(v.startswith("mulran") for v in et.VARIANTS)
