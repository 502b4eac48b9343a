"""The defaults a parameter YAML documents: its commented-out lines ``# group/name: value  # comment``."""

import re

import yaml

_LINE = re.compile(r"#\s*([a-z_]+(?:/[a-z_]+)*):\s*(\"[^\"]*\"|\[[^\]]*\]|[^\s#]+)")


def documented_defaults(text: str) -> dict:
    """``{"group/name": value}`` of the commented-out parameter lines of ``text``."""
    out = {}
    for line in text.splitlines():
        match = _LINE.match(line)
        if match:
            out[match.group(1)] = yaml.safe_load(match.group(2))
    return out
