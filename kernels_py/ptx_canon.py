"""Canonical numbering of PTX virtual registers.

NVRTC (CUDA 13.4, inside warp-lang 1.19) is not deterministic for every module: compiling the same
CUDA source twice, even in one process, can give PTX whose virtual registers are numbered
differently (e.g. a constant lands in %f134 one time and %f135 the next). Register names in PTX
are only names: ptxas allocates physical registers itself. So compile.py renumbers each
function's registers in order of first appearance, which makes the output a function of the
program alone and lets CI check that ptx/ regenerates byte for byte.

Only register families declared with a range (`.reg .f32 %f<148>;`) are renumbered, and each
family keeps its count, so the declarations stay valid. Special registers (%tid, %clock64, ...)
are never declared that way and are left alone.
"""

from __future__ import annotations

import re

_RANGE_DECL = re.compile(r"^\s*\.reg\s+\.\w+\s+%([A-Za-z_]+)<(\d+)>;", re.MULTILINE)
_FUNC_START = re.compile(r"^\s*(?:\.visible\s+|\.weak\s+|\.extern\s+)?\.(?:entry|func)\b", re.MULTILINE)


def _function_spans(text: str):
    """(start, end) of each function body: from its `{` to the matching `}`."""
    spans = []
    for match in _FUNC_START.finditer(text):
        open_at = text.find("{", match.end())
        semicolon = text.find(";", match.end())
        if open_at < 0 or (0 <= semicolon < open_at and ")" not in text[match.end():semicolon + 1]):
            continue  # a declaration (prototype), no body
        depth = 0
        for i in range(open_at, len(text)):
            c = text[i]
            if c == "{":
                depth += 1
            elif c == "}":
                depth -= 1
                if depth == 0:
                    spans.append((open_at, i + 1))
                    break
    return spans


def _renumber(body: str) -> str:
    families = {name: int(count) for name, count in _RANGE_DECL.findall(body)}
    if not families:
        return body
    # Longest names first, so that %rd12 is not read as %r followed by "d12".
    names = sorted(families, key=len, reverse=True)
    pattern = re.compile(r"%(" + "|".join(map(re.escape, names)) + r")(\d+)\b")
    mapping: dict[tuple[str, int], int] = {}
    next_id = {name: 0 for name in families}

    def rename(m: re.Match) -> str:
        key = (m.group(1), int(m.group(2)))
        new = mapping.get(key)
        if new is None:
            new = next_id[key[0]]
            next_id[key[0]] += 1
            mapping[key] = new
        return f"%{key[0]}{new}"

    out = pattern.sub(rename, body)
    for name, used in next_id.items():
        if used > families[name]:
            raise ValueError(f"register %{name}{used - 1} is outside its declared range %{name}<{families[name]}>")
    return out


def canonicalize(ptx: bytes) -> bytes:
    """The same PTX with every function's virtual registers numbered by first appearance."""
    nul = ptx.endswith(b"\0")
    text = ptx.rstrip(b"\0").decode("utf-8")
    pieces = []
    last = 0
    for start, end in _function_spans(text):
        pieces.append(text[last:start])
        pieces.append(_renumber(text[start:end]))
        last = end
    pieces.append(text[last:])
    out = "".join(pieces).encode("utf-8")
    return out + b"\0" if nul else out
