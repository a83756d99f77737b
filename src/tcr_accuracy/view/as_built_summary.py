"""What the forms of a calibration reach, in words and tables for people (mm, labelled).

Used by ``tcr-accuracy export`` (printed summary, the URDF's comment, the UR file's header),
by ``diagnose --as-built-urdf`` and by the calibration report's "what to do next". The figures
come from :class:`~tcr_accuracy.asbuilt.accuracy.FormAccuracy` records (or their JSON dicts).
"""

from __future__ import annotations

import numpy as np

#: How each kind of figure is named, in the order they are shown.
KINDS = (("held-out", "held-out"), ("k-fold held-out", "k-fold held-out"), ("measured", "on the measured poses"))


def accuracy_records(accuracy) -> list[dict]:
    return [a if isinstance(a, dict) else a.to_dict() for a in accuracy]


def accuracy_lines(accuracy) -> list[str]:
    """The printed table: one line per form, mean / RMS / max [mm] per kind of data."""
    records = accuracy_records(accuracy)
    kinds = [(k, label) for k, label in KINDS if any(r["on"] == k for r in records)]
    forms = list(dict.fromkeys(r["form"] for r in records))
    files = {r["form"]: r["file"] for r in records}
    names = {form: f"{form} ({files[form]})" if files[form] else form for form in forms}
    width = max(len(n) for n in [*names.values(), "form (file)"]) + 2
    table = {}
    for form in forms:
        for kind, _ in kinds:
            r = next((r for r in records if r["form"] == form and r["on"] == kind), None)
            table[form, kind] = "" if r is None else f"{r['mean_mm']:.4f} / {r['rms_mm']:.4f} / {r['max_mm']:.4f}"
    # each column as wide as its widest cell and two spaces (26 at least): figures past 100 mm stay apart
    widths = {kind: max(26, len(label) + 2, *(len(table[form, kind]) + 2 for form in forms)) for kind, label in kinds}
    header = "  " + "form (file)".ljust(width) + "".join(f"{label:>{widths[kind]}}" for kind, label in kinds)
    lines = ["  TCP position error, mean / RMS / max [mm], each form with its own tracker frame fitted on the "
             "measured poses:", header]
    for form in forms:
        lines.append("  " + names[form].ljust(width) + "".join(f"{table[form, kind]:>{widths[kind]}}"
                                                              for kind, _ in kinds))
    data = {r["on"]: r for r in records}
    for kind, label in kinds:
        lines.append(f"  {label}: {data[kind]['data']} ({data[kind]['n']} poses)")
    if "nominal" in forms:
        lines.append(f"  nominal: {NOMINAL_WORDS}")
    return lines


#: What the nominal line is (prediction.nominal's definition), in the words predict and compensate print too.
NOMINAL_WORDS = ("the nominal robot, tracker frame and TCP offset fitted to the measured poses (the figure predict "
                 "and compensate print)")


def headline(accuracy) -> str:
    """One sentence: what the full model, the URDF and the nominal robot reach on the best data there is."""
    records = accuracy_records(accuracy)
    for kind, label in KINDS:
        rows = {r["form"]: r for r in records if r["on"] == kind}
        if "URDF alone" in rows or "full model" in rows:
            parts = [f"{form} {rows[form]['mean_mm']:.4f} mm" for form in ("full model", "URDF alone",
                                                                          "UR calibration file", "nominal")
                     if form in rows]
            return f"TCP position error, mean {label} ({next(iter(rows.values()))['data']}): " + "; ".join(parts)
    return ""


def urdf_comment(export, diagnosis: str) -> str:
    """The comment at the top of the calibration URDF."""
    geometry = export.geometry
    return (f"Calibrated {export.model.robot.name} from {diagnosis}, written by tcr-accuracy. The joint origins "
            f"hold the geometry and joint zero offsets refitted to the full model over {geometry.n_measured} measured "
            f"poses and {geometry.n_sampled} between them (RMS {geometry.rms * 1e3:.4f} mm from the full model); "
            f"{export.model.robot.tool_frame} is where the maker put it, the measured point is the frame "
            f"{export.measured_frame}. " + _start_sentence(export) + headline(export.accuracy)
            + ". Compliance, gear errors and the other "
            f"non-geometric effects are not in a URDF: the full model ({export.model_file}, tcr_accuracy.load_as_built) "
            "or the compensation filter carry them.")


def ur_file_header(export) -> str:
    """Comment lines at the top of the UR calibration file: what it is, the TCP to set, its accuracy."""
    offset = export.measured_offset
    rotation = _rotation_vector(offset[:3, :3])
    tcp = ", ".join(f"{v:.9g}" for v in (*offset[:3, 3], *rotation))
    return "\n".join([
        f"# Kinematics calibration of {export.model.robot.name} for Universal Robots' ROS 2 description",
        "# (ur_description's kinematics_parameters_file), written by tcr-accuracy export.",
        "# The controller's own factory calibration has another hash: the driver reports the mismatch.",
        f"# Measured point on tool0, to set as the TCP: p[{tcp}] (m, rad; rotation vector)",
        *([f"# {_start_sentence(export).strip()}"] if export.model.robot.kinematics else []),
        f"# {headline(export.accuracy)}",
    ]) + "\n"


def urdf_phrase(accuracy) -> str:
    """What the calibration URDF and the nominal robot reach, in a few words ("" without figures)."""
    records = accuracy_records(accuracy)
    for kind, label in KINDS:
        rows = {r["form"]: r for r in records if r["on"] == kind}
        if "URDF alone" in rows and "nominal" in rows:
            return (f"{rows['URDF alone']['file']} {rows['URDF alone']['mean_mm']:.4f} mm mean {label}, the nominal "
                    f"URDF {rows['nominal']['mean_mm']:.4f} mm")
    return ""


def _rotation_vector(rotation: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rotation).as_rotvec()


def _start_sentence(export) -> str:
    """'The start was the factory kinematics of FILE (...): ...' when the nominal robot was the robot's
    own kinematics (``--kinematics``), else ''."""
    start = export.model.robot.kinematics
    if not start:
        return ""
    return (f"The start (the nominal robot) was {export.model.robot.name} with the factory kinematics of "
            f"{start['file']} ({start['format']}, sha256 {start['sha256'][:12]}); the diagnosis and the tables' "
            "corrections are relative to it, this file holds the whole calibrated kinematics. ")
