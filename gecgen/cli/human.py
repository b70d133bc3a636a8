"""The short summary a person reads; --json prints the full record."""
from __future__ import annotations


def warning_lines(caught) -> list[str]:
    """The lines the terminal prints for recorded warnings: each one's first line, once, in order."""
    return list(dict.fromkeys(str(w.message).splitlines()[0] for w in caught))


def scalar(value) -> str:
    """A value as a person reads it: three significant digits, as the reports print them, and every
    digit before the point of a number of 1000 or more (a time in seconds, a log det); `-` for a value
    not known (JSON null), `none` for an empty list and `yes` or `no` for a truth, not Python's spellings."""
    if value is None:
        return "-"
    if hasattr(value, "item") and getattr(value, "ndim", None) == 0:  # numpy's scalars read as Python's
        value = value.item()
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, list):  # an interval: [low, high]
        return "[" + ", ".join(map(scalar, value)) + "]" if value else "none"
    if not isinstance(value, float):
        return str(value)
    return f"{value:.0f}" if abs(value) >= 1e3 else f"{value:.3g}"


def _interval(value) -> bool:
    return isinstance(value, list) and len(value) == 2 and all(isinstance(v, float) for v in value)


#: list entries a person sees one per line before the rest is left to --json
MAX_LISTED = 20


def print_human(result: dict):
    """A short summary for a person; the full record (every list entry) is what --json prints. A
    dict whose units are given beside it (`<key>_units`, one per entry) is printed with them."""
    for key, value in result.items():
        # the warnings are on stderr already, one line each
        if key in ("identifiable", "training_ranges", "warnings") or (key.endswith("_units") and key[:-6] in result):
            continue
        # the verdict's next step (identify --cameras gives it alone, as `next_step`) says what to do, once
        if key == "next" and ("assessment" in result or "next_step" in result):
            continue
        units = result.get(f"{key}_units", {})
        if key == "outliers":
            print(f"outliers: {len(value)}" + (" (file row, pose, target, residual)" if value else ""))
            for o in value[:MAX_LISTED]:
                rotation = f", {o['rotation_mrad']:.3f} mrad" if "rotation_mrad" in o else ""
                print(f"  row {o['row']}: pose {o['pose']} {o['target']} {o['residual_mm']:.3f} mm{rotation}")
            if len(value) > MAX_LISTED:
                print(f"  ... {len(value) - MAX_LISTED} more (use --json for the list)")
        elif key == "candidates":
            print(f"candidates: {len(value)} (cross-validated on the training poses)")
            for c in value:
                score = f"{c['cv_rms_mm']:.3g} mm" if c["cv_rms_mm"] is not None else f"not fitted: {c['refused']}"
                print(f"  {c['model']}: {score}")
        elif key == "assessment":
            print(f"verdict: {value['verdict']}. {value['statement']}")
            for line in value["limits"]:
                print(f"  limits it: {line}")
            print(f"next step: {value['next_step']}")
        elif key == "table":
            print_error_table(value)
        elif key == "camera_uncertainty":
            print("camera poses, 1 sigma (" + value["covariance"] + "): " + ("; ".join(
                f"{name} in the {'tool frame' if v['relative_to'] == 'tool' else v['relative_to'] + ' frame'} "
                f"{v['translation_mm']:.3g} mm, {v['rotation_mrad']:.3g} mrad" for name, v in value["cameras"].items())
                or "one fixed camera: nothing to place it against"))
        elif key == "fixtures" and value and "poses" in value[0]:
            print(f"fixtures: {len(value)} (configurations chosen, of the candidates that reach it)")
            for f in value:
                print(f"  {f['name']} ({f['kind']}): {f['poses']} of {f['candidates']}")
        elif key == "by_fixtures":
            print("the same poses over the first k fixtures (log det; predicted held-out error the coefficients add):")
            for b in value:
                v = b["predicted_rms_mm"]
                print(f"  {b['fixtures']}: " + (f"{b['log_det']:.1f}; {v:.3g} mm" if v is not None
                                                else "leaves coefficients undetermined"))
        elif key == "effects":
            print(f"effects: {len(value)}")
            for e in value:
                print(f"  {e['error']}: {', '.join(e['terms'])} ({e['family']}; cross-validated gain "
                      f"{e['gain_mm']:.3g} mm)")
        elif isinstance(value, list) and value and all(isinstance(v, str) for v in value):
            print(f"{key}:")
            for line in value[:MAX_LISTED]:
                print(f"  {line}")
            if len(value) > MAX_LISTED:
                print(f"  ... {len(value) - MAX_LISTED} more (use --json for the list)")
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            print(f"{key}: {len(value)} (use --json for the list)")
        elif isinstance(value, dict):
            scalars = {k: v for k, v in value.items() if not isinstance(v, (dict, list)) or _interval(v)}
            if not scalars:  # records by name (cameras, branches) or parts of one (a board's pose): their names
                names = list(value)
                shown = ", ".join(map(str, names[:MAX_LISTED])) + (f" and {len(names) - MAX_LISTED} more"
                                                                  if len(names) > MAX_LISTED else "")
                print(f"{key}: {shown} (use --json for them)")
                continue
            more = " (more with --json)" if len(scalars) < len(value) else ""
            print(f"{key}: " + ", ".join(f"{k} {scalar(v)}{' ' + units[k] if k in units else ''}"
                                         for k, v in scalars.items()) + more)
        else:
            print(f"{key}: {scalar(value)}")


def _cell(value, std) -> str:
    if value is None:
        return "-"
    return f"{value:.3g}" + (f" +-{std:.2g}" if std is not None else "")


def print_error_table(table: dict):
    """`gecgen export --table`: joint zero offsets, then the constant errors of every frame."""
    print("joint zero offsets (value +-std; coefficient):")
    width = max(len(z["joint"]) for z in table["zero_offsets"])
    for z in table["zero_offsets"]:
        if z["value"] is None:
            print(f"  {z['joint']:<{width}}  -  ({z['why']})")
            continue
        swap = f", exchanged for {z['exchanged_for']}" if z["exchanged_for"] else ""
        print(f"  {z['joint']:<{width}}  {_cell(z['value'], z['std'])} {z['unit']}  ({z['coefficient']}{swap})")
    keys = [k for k in table["frames"][0] if k not in ("frame", "std")]
    print("constant errors per frame (value +-std; 0 without std: eliminated; -: a zero offset or not in the model):")
    print("  frame" + "".join(f" {k:>19}" for k in keys))
    for f in table["frames"]:
        print(f"  {f['frame']:<5}" + "".join(f" {_cell(f[k], f['std'][k]):>19}" for k in keys))
    change = table["reexpressed_change_mm"]
    print("re-expressed with the zero offsets kept: the targets move by "
          + (f"{change:.2g} mm at most" if change >= 5e-7 else "less than 0.000001 mm"))
