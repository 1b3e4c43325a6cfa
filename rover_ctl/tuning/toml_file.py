"""A rule-base document (the dict ``tomllib`` reads from a rule-base file) written back as TOML
that ``load_rulebase`` reads: the tuned rule base's file. Only the shapes the format has
(docs/fuzzy.md): top-level scalars, ``[inputs.NAME]`` and ``[outputs.NAME]`` tables whose
``sets`` is an inline table of number lists, and ``[rules] list``."""

from __future__ import annotations

import json
import math
import re
from typing import Any

BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(name: str) -> str:
    return name if BARE_KEY.match(name) else json.dumps(name)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)  # a TOML basic string has JSON's escapes
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {type(value).__name__} as TOML")


def to_toml(document: dict[str, Any], comment: list[str] = ()) -> str:
    """The document as TOML text, ``comment`` lines first."""
    lines = [f"# {line}".rstrip() for line in comment]
    if lines:
        lines.append("")
    for key, value in document.items():
        if key not in ("inputs", "outputs", "rules"):
            lines.append(f"{_key(key)} = {_value(value)}")
    for kind in ("inputs", "outputs"):
        for name, spec in document.get(kind, {}).items():
            lines += ["", f"[{kind}.{_key(name)}]"]
            lines += [f"{_key(k)} = {_value(v)}" for k, v in spec.items()]
    rules = document.get("rules", {})
    lines += ["", "[rules]", "list = ["]
    lines += [f"  {_value(rule)}," for rule in rules.get("list", [])]
    lines.append("]")
    return "\n".join(lines) + "\n"
