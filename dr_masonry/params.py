"""Scene parameters: ``key=value`` overrides of a case's PARAMS defaults, checked and typed."""
import ast
import json
import math
import os
import sys

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}


class ParameterError(ValueError):
    """A bad ``key=value`` override; the message names the key, the value and what is valid."""


def _coerce(key, text, default):
    """Convert ``text`` to the type of ``default``."""
    try:
        if isinstance(default, bool):
            low = text.strip().lower()
            if low in _TRUE | _FALSE:
                return low in _TRUE
            raise ValueError(f"expected one of {sorted(_TRUE | _FALSE)}")
        if isinstance(default, int):
            v = float(text) if any(c in text for c in ".eE") else int(text)
            if isinstance(v, float) and not v.is_integer():
                raise ValueError("expected an integer")
            return int(v)
        if isinstance(default, float):
            v = float(text)
            if not math.isfinite(v):   # inf and nan would surface later, under another name
                raise ValueError("expected a finite number")
            return v
        if isinstance(default, str):
            return text
        if isinstance(default, (list, tuple)):
            items = [s for s in text.strip("[]()").split(",") if s.strip()]
            ref = default[0] if len(default) else ""
            out = [_coerce(key, s.strip(), ref) for s in items]
            return type(default)(out)
        if isinstance(default, dict):
            v = json.loads(text)
            if not isinstance(v, dict):
                raise ValueError("expected a JSON object")
            return v
        try:                     # None or another type: a Python literal, else the string
            return ast.literal_eval(text)
        except (ValueError, SyntaxError):
            return text
    except ParameterError:
        raise
    except (ValueError, json.JSONDecodeError) as e:
        raise ParameterError(f"parameter {key}={text!r}: cannot convert to "
                         f"{type(default).__name__} like the default {default!r} ({e})") from None


def with_preset(defaults, preset, on):
    """A new dict: ``defaults`` with the values of ``preset`` (a scene's ``FAST``) on top when
    ``on`` is true, else a copy of ``defaults``."""
    return dict(defaults, **preset) if on else dict(defaults)


def output_path(params, key="out"):
    """``params[key]``, the path stem of a scene's outputs (``out.h5``, ``out.png``, ...), after
    checking that it names a file: not blank, not a folder (ending in a separator)."""
    out = str(params[key])
    if not out.strip() or out.endswith(("/", os.sep)):
        raise ParameterError(f"parameter {key}={params[key]!r}: must name the results' path stem "
                             "(e.g. results/wall: results/wall.h5, .png, .csv, _vtk/)")
    return out


def format_params(params):
    """The parameters as aligned ``key = value`` lines."""
    w = max((len(k) for k in params), default=0)
    return "\n".join(f"  {k:<{w}} = {v!r}" for k, v in params.items())


#: parameters that shape one loading protocol's path only (the wall and house scenes S4-S7); the
#: other protocol would ignore them
PROTOCOL_KEYS = {"monotonic": ("drift", "target", "increments", "grading"),
                 "cyclic": ("step", "quarter_increments", "n_amplitudes")}


def check_protocol_keys(params, given):
    """ParameterError for a parameter among ``given`` (the keys set explicitly) that the chosen
    ``params["protocol"]`` would ignore (``step`` for a monotonic run, ``increments`` for a
    cyclic one): the run would not be the one asked for. Scenes without a protocol pass, and so
    does an unknown protocol (the scene's own check names the valid ones)."""
    if params.get("protocol") not in PROTOCOL_KEYS:
        return
    mine = PROTOCOL_KEYS[params["protocol"]]
    for protocol, keys in PROTOCOL_KEYS.items():
        stray = [k for k in keys if k in given and k in params and k not in mine]
        if stray:
            raise ParameterError(f"parameter {stray[0]}={params[stray[0]]!r} shapes the {protocol} "
                                 f"path only; this run is protocol={params['protocol']} (its path: "
                                 f"{', '.join(k for k in mine if k in params)})")


def parse_overrides(params, argv=None, doc=None):
    """Defaults ``params`` updated by ``key=value`` arguments.

    Parameters
    ----------
    params : dict
        the case's PARAMS (defaults; their types drive the conversion: bool accepts
        true/false/yes/no/on/off/1/0, int accepts ``1e3``, list/tuple a comma-separated list
        of the first element's type, dict JSON, None any Python literal or a string).
    argv : list of str, optional
        the arguments (default ``sys.argv[1:]``). ``-h``/``--help`` prints ``doc`` and the
        defaults and exits (SystemExit 0).
    doc : str, optional
        the case's docstring for ``--help``.

    Returns
    -------
    dict
        a new dict (``params`` is not modified).

    Raises
    ------
    ParameterError
        an argument that is not ``key=value``, an unknown key (the message lists the valid keys)
        or a value that does not convert.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    if any(a in ("-h", "--help") for a in argv):
        print((doc or "").strip())
        print("\nParameters (override with key=value):")
        print(format_params(params))
        raise SystemExit(0)
    out = dict(params)
    for arg in argv:
        key, sep, text = arg.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ParameterError(f"argument {arg!r} is not key=value; valid keys: "
                             f"{', '.join(params)}")
        if key not in params:
            raise ParameterError(f"unknown parameter {key!r}; valid keys: {', '.join(params)}")
        out[key] = _coerce(key, text, params[key])
    return out

