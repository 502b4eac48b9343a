"""CPU and memory over repeated runs of each mode (`gpm experiment --repeats`): the median of each figure over the
runs, and the spread of the per-run means, also as each run's ratio to the baseline's run of the same round. The
runs of a round follow each other (experiment.modes.interleaved_runs), so a ratio within a round sees the same
state of the machine. Pure: no ROS."""

from __future__ import annotations

import statistics
from collections.abc import Mapping, Sequence

from grid_puzzle_localization.evaluation.resources import RESOURCE_METRICS
from grid_puzzle_localization.util.iteration import zip_equal

SPREAD_METRICS = ("cpu_percent", "rss_bytes")  # the first table's figures


def median_of(values: Sequence[float | int | None]) -> float | int | None:
    """The median; None when any value is missing. One value is returned as it is."""
    if not values or any(v is None for v in values):
        return None
    return statistics.median(values)


def value_range(values: Sequence[float | None]) -> dict[str, float | None]:
    """min and max; both None when any value is missing."""
    if not values or any(v is None for v in values):
        return {"min": None, "max": None}
    return {"min": min(values), "max": max(values)}


def median_resources(per_repeat: Sequence[Mapping]) -> dict:
    """The resources of each run of one mode (evaluation.resources.mode_resources, in run order) as one dictionary of
    the same shape: each statistic of each metric the median over the runs; the process lists of the first run."""
    first = per_repeat[0]
    out: dict = {}
    for protocol, r in first.items():
        out[protocol] = {"processes": list(r["processes"])}
        for metric in RESOURCE_METRICS:
            out[protocol][metric] = {
                stat: median_of([p[protocol][metric][stat] for p in per_repeat]) for stat in r[metric]
            }
    return out


def ratio(value: float | None, baseline: float | None) -> float | None:
    """``value`` over ``baseline``; None when either is missing or the baseline is not positive."""
    return value / baseline if value is not None and baseline is not None and baseline > 0 else None


def repeat_spread(per_repeat: Mapping[str, Sequence[Mapping]], baseline: str) -> dict:
    """Per mode, protocol and metric (SPREAD_METRICS): the mean of each run in run order (``means``) with their min
    and max, and, when the baseline mode ran, each run's mean over the baseline's mean of the same round
    (``vs_baseline``: ``per_repeat``, min, max)."""
    base = per_repeat.get(baseline)
    out: dict = {}
    for mode, runs in per_repeat.items():
        out[mode] = {}
        for protocol in runs[0]:
            entry = {}
            for metric in SPREAD_METRICS:
                means = [r[protocol][metric]["mean"] for r in runs]
                entry[metric] = {"means": means, **value_range(means)}
                if base is not None:
                    bases = [b[protocol][metric]["mean"] for b in base]
                    ratios = [ratio(v, b) for v, b in zip_equal(means, bases)]
                    entry[metric]["vs_baseline"] = {"per_repeat": ratios, **value_range(ratios)}
            out[mode][protocol] = entry
    return out
