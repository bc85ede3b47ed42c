"""A bag's ``metadata.yaml`` as rosbag2 writes it, dumped in pieces so that rewriting it after
every split costs only what changed (:class:`MetadataYaml`)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

DUMPER: Any = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
"""libyaml's dumper when PyYAML has it: metadata.yaml is rewritten after every split."""


INFO_KEY = "rosbag2_bagfile_information"


def dump_yaml(data: Any) -> str:
    return str(yaml.dump(data, Dumper=DUMPER, sort_keys=False, width=10**9))


class MetadataYaml:
    """The YAML of a metadata dict (under ``wrapper``), the same text as one ``yaml.dump``
    but made of pieces dumped once: every entry of a list (files, topics) and of
    ``custom_data``, in its place. A split then dumps only what changed (times and counts)
    instead of the whole, ever-growing file list: the dump was the largest part of a split,
    which the supervisor waits for between trials."""

    def __init__(self, wrapper: str | None) -> None:
        self.wrapper = wrapper
        self._pieces: dict[tuple[str, str], str] = {}

    def dump(self, info: Mapping[str, Any]) -> str:
        """``yaml.dump({wrapper: info})`` (or of ``info`` without a wrapper)."""
        used: dict[tuple[str, str], str] = {}

        def piece(key: str, value: Any, skip: int) -> str:
            """``{key: value}`` in its place, without its first ``skip`` lines."""
            cache_key = (key, repr(value))
            text = used.get(cache_key) or self._pieces.get(cache_key)
            if text is None:
                data = {key: value} if self.wrapper is None else {self.wrapper: {key: value}}
                lines = dump_yaml(data).splitlines(keepends=True)
                text = "".join(lines[skip + (self.wrapper is not None):])
            used[cache_key] = text
            return text

        indent = "" if self.wrapper is None else "  "
        parts = [] if self.wrapper is None else [f"{self.wrapper}:\n"]
        for key, value in info.items():
            if _counts(value):  # times and counts change with every split: formatted here
                parts.append(f"{indent}{key}: {value}\n" if isinstance(value, int) else
                             f"{indent}{key}:\n" + "".join(f"{indent}  {k}: {v}\n"
                                                             for k, v in value.items()))
            elif isinstance(value, list) and value:
                parts.append(piece(key, [], 0).replace(" []", ""))
                for item in value:
                    last = list(item)[-1] if isinstance(item, dict) and len(item) > 1 else None
                    if last is not None and _counts(item[last]):  # a topic's message count
                        parts.append(piece(key, [{k: v for k, v in item.items() if k != last}],
                                           1) + f"{indent}  {last}: {item[last]}\n")
                    else:
                        parts.append(piece(key, [item], 1))
            elif isinstance(value, dict) and value and key == "custom_data":
                parts.append(piece(key, {}, 0).replace(" {}", ""))
                parts.extend(piece(key, {k: v}, 1) for k, v in value.items())
            else:
                parts.append(piece(key, value, 0))
        self._pieces = used
        return "".join(parts)


def _counts(value: Any) -> bool:
    """An int, or a dict of ints under plain keys (``{"nanoseconds": 5}``)."""
    if isinstance(value, dict):
        return bool(value) and all(isinstance(v, int) and not isinstance(v, bool) and
                                   k.isidentifier() for k, v in value.items())
    return isinstance(value, int) and not isinstance(value, bool)
