"""Minimal text-level editing of libconfig scene files (no libconfig binding
needed): read a setting's value and replace or add one, keeping every other
byte of the file, comments included.

Paths are dotted group names, e.g. "wheel.slip", "run.end_time",
"dem.output.every". Only settings inside groups ({ ... }) are addressed;
lists and arrays are skipped over as values.
"""
import re


class SceneError(Exception):
    pass


def _skip_ws(text, i):
    n = len(text)
    while i < n:
        c = text[i]
        if c in " \t\r\n":
            i += 1
        elif c == "#" or text.startswith("//", i):
            j = text.find("\n", i)
            i = n if j < 0 else j + 1
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            if j < 0:
                raise SceneError("unterminated /* comment")
            i = j + 2
        else:
            break
    return i


def _skip_string(text, i):
    j = i + 1
    while j < len(text):
        if text[j] == "\\":
            j += 2
            continue
        if text[j] == '"':
            return j + 1
        j += 1
    raise SceneError("unterminated string")


def _value_end(text, i):
    """End of the value starting at i (exclusive), before any ';' or ','."""
    n = len(text)
    depth = 0
    while i < n:
        i2 = _skip_ws(text, i)
        if i2 != i:
            if depth == 0:
                return i
            i = i2
            continue
        c = text[i]
        if c == '"':
            i = _skip_string(text, i)
            # adjacent string literals concatenate
            continue
        if c in "{[(":
            depth += 1
        elif c in "}])":
            if depth == 0:
                return i
            depth -= 1
            if depth == 0:
                return i + 1
        elif c in ";," and depth == 0:
            return i
        i += 1
    return i


_NAME = re.compile(r"[A-Za-z*][-A-Za-z0-9_*]*")


def _settings(text, i, end):
    """Yields (name, name_start, value_start, value_end, setting_end) of the
    settings of the group whose body spans text[i:end]."""
    while True:
        i = _skip_ws(text, i)
        if i >= end:
            return
        m = _NAME.match(text, i)
        if not m:
            raise SceneError("expected a setting name at offset %d: %r" % (i, text[i:i + 30]))
        name = m.group(0)
        j = _skip_ws(text, m.end())
        if j >= end or text[j] not in "=:":
            raise SceneError("expected '=' after %s" % name)
        v0 = _skip_ws(text, j + 1)
        v1 = _value_end(text, v0)
        k = _skip_ws(text, v1)
        if k < end and text[k] in ";,":
            k += 1
        yield name, i, v0, v1, k
        i = k


def _find(text, path):
    """(value_start, value_end) of `path`, or raise KeyError with the
    group span (body_start, body_end) where it would go."""
    parts = path.split(".")
    lo, hi = 0, len(text)
    for depth, part in enumerate(parts):
        found = None
        for name, _n0, v0, v1, _e in _settings(text, lo, hi):
            if name == part:
                found = (v0, v1)
        if found is None:
            raise KeyError((path, depth, lo, hi))
        if depth == len(parts) - 1:
            return found
        v0, v1 = found
        if text[v0] != "{":
            raise SceneError("%s is not a group" % ".".join(parts[:depth + 1]))
        lo, hi = v0 + 1, v1 - 1


def get(text, path):
    """The value text of `path` (e.g. '0.05', '"default"', '[0.1, 0.2]')."""
    v0, v1 = _find(text, path)
    return text[v0:v1]


def get_float(text, path, default=None):
    try:
        return float(get(text, path))
    except KeyError:
        if default is None:
            raise
        return default


def set_value(text, path, value, note=None):
    """Returns text with `path` set to the value text `value` (added at the
    end of its group when absent; the groups above it must exist). With
    `note`, a '#' comment at the end of that line is replaced by '# note'."""
    try:
        v0, v1 = _find(text, path)
        out = text[:v0] + value + text[v1:]
        if note is not None:
            a = v0 + len(value)
            eol = out.find("\n", a)
            eol = len(out) if eol < 0 else eol
            h = out.find("#", a, eol)
            if h >= 0 and '"' not in out[a:h]:
                out = out[:h] + "# " + note + out[eol:]
        return out
    except KeyError as e:
        _p, depth, lo, hi = e.args[0]
        parts = path.split(".")
        if depth != len(parts) - 1:
            raise SceneError("group %s not in the scene" % ".".join(parts[:depth + 1]))
        # on its own line before the closing brace of the group (a one-line
        # group gets it before the brace), or at the end of the file
        if depth == 0:
            return text.rstrip("\n") + "\n%s = %s;\n" % (parts[-1], value)
        nl = text.rfind("\n", lo, hi)
        if nl >= 0 and text[nl + 1:hi].strip() == "":
            ins, add = nl + 1, "  %s = %s;\n" % (parts[-1], value)
        else:
            ins, add = hi, " %s = %s; " % (parts[-1], value)
        return text[:ins] + add + text[ins:]


def format_value(v):
    """Python value -> libconfig value text (floats always with a point)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        s = repr(v)
        return s if any(c in s for c in ".eEn") else s + ".0"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(v)


def parse_override(s):
    """'wheel.travel_distance=0.03' -> ('wheel.travel_distance', '0.03');
    a bare number that libconfig would read as an integer keeps its form,
    so write 0.03 or 3.0 for floats."""
    if "=" not in s:
        raise SceneError("override %r: expected KEY=VALUE" % s)
    k, v = s.split("=", 1)
    return k.strip(), v.strip()
