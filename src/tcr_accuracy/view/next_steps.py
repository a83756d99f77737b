"""What to do after a diagnosis, one sentence a step: what ``tcr-accuracy diagnose`` prints last and
the calibration report's "What to do next" (the same steps, from the diagnosis' JSON form).

Each step is something a person does: plan poses (the command), measure them (the file), diagnose
again (the command), check a part of the robot, load the calibration (the command). Effects are
named in words (each effect class's ``in_words``), never as vocabulary sets; every command is one
that finishes (``plan-poses`` with its default I-optimal design, not the T-optimal one that
diagnoses the measurements first).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from .page_blocks import Code

#: how many poses the next campaign measures
NEXT_POSES = 30
#: the file plan-poses writes the poses to, and the one their measurements go into
PLANNED_FILE = "next_poses.csv"
MEASURED_FILE = "next_poses_measured.csv"  # as plan-poses names it


@dataclass(frozen=True)
class Step:
    """One sentence: text and commands (:class:`~tcr_accuracy.view.page_blocks.Code`) in order;
    ``kind`` is ``"step"`` for what to do, ``"check"`` for what to check on the robot (the report may
    leave checks out of a full page)."""

    parts: tuple
    kind: str = "step"

    def text(self, quote: str = "") -> str:
        """The sentence as plain text, each command between ``quote`` marks."""
        return "".join(f"{quote}{p.text}{quote}" if isinstance(p, Code) else str(p) for p in self.parts)


def effect_in_words(name: str) -> str:
    """An effect, or effects joined by ``+`` (an ambiguity group's member with its companion), in
    plain words: ``compliance+encoder_scale`` -> "joints giving way under gravity with a gear-ratio
    error". A name outside the vocabulary is kept as it is."""
    from ..effects import effect_class

    words = []
    for part in name.split("+"):
        try:
            cls = effect_class(part)
        except Exception:  # an effect this installation does not know (a newer JSON): its name
            words.append(part)
            continue
        words.append(cls.in_words or cls.summary or part)
    return " with ".join(words)


def _alternatives(group: dict | list) -> tuple[str, list[str]]:
    """The chosen effect of an ambiguity group and the single effects that stand in for it (each
    member split at ``+``, the chosen one and repeats left out), in the group's order."""
    effects = list(group["effects"] if isinstance(group, dict) else group)
    chosen = group.get("chosen", effects[0]) if isinstance(group, dict) else effects[0]
    others: list[str] = []
    for member in effects:
        for part in member.split("+"):
            if part != chosen and part not in others:
                others.append(part)
    return chosen, others


def _listed(items: list[str], last: str) -> str:
    """"a", "a or b", "a, b or c"."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + f" {last} " + items[-1]


def next_steps(d: dict, *, measurements: list[str], robot_options: str = "",
               ) -> list[Step]:
    """The steps after a diagnosis.

    Parameters
    ----------
    d : dict
        The diagnosis in its JSON form (``Diagnosis.to_dict()`` or a ``diagnose --json`` file):
        ``ambiguous``, ``structure_verdict`` (or ``structure_remains``), ``physical``,
        ``outside_physics``.
    measurements : list of str
        The measurement files as the user names them: ``plan-poses`` reads the first (one tracker
        frame), the next ``diagnose`` all of them and the new one.
    robot_options : str, default=""
        ``--robot ... --tool ...`` as the commands need them ("" for the built-in tool-changer).

    Returns
    -------
    list of Step
        In the order to do them: the next poses (plan them, measure them, diagnose again), then
        the checks on the robot.
    """
    files = [f for f in measurements if f] or ["MEASUREMENTS.csv"]
    quoted = " ".join(shlex.quote(f) for f in files)
    groups = list(d.get("ambiguous") or [])
    verdict = d.get("structure_verdict") or ("yes" if d.get("structure_remains") else "no")
    if groups:
        chosen = [effect_in_words(_alternatives(g)[0]) for g in groups]
        purpose = f"to tell {_listed(chosen, 'and')} from what fits as well"
    elif verdict in ("yes", "cannot tell"):
        purpose = ("where the model is least known (structure "
                   f"{'remains' if verdict == 'yes' else 'may remain'} in the residual)")
    else:
        purpose = "to confirm the calibration"
    steps = [Step((f"Measure the {NEXT_POSES} poses ",
                   Code(f"tcr-accuracy plan-poses {shlex.quote(files[0])}{robot_options} -k {NEXT_POSES} "
                        f"--out {PLANNED_FILE}"),
                   f" chooses {purpose}, into {MEASURED_FILE}; then run ",
                   Code(f"tcr-accuracy diagnose {quoted} {MEASURED_FILE}{robot_options}"), "."))]
    for g in groups:
        chosen, others = _alternatives(g)
        if others:
            words = [effect_in_words(e) for e in (chosen, *others)]
            steps.append(Step((f"Until then, check on the robot which of these it is: {_listed(words, 'or')} (they "
                               "explain the data equally well).",), kind="check"))
    for effect, info in (d.get("physical") or {}).items():
        for p in info.get("pinned", []):
            steps.append(Step((f"Check {p.get('parameter')} on the robot: the fit holds it on its physical bound "
                               f"({p.get('bound')}).",), kind="check"))
        if not info.get("plausible", True):
            steps.append(Step((f"Check {effect_in_words(effect)} on the robot: the fitted values lie outside physics"
                               f" ({info.get('reason', '')}).",), kind="check"))
    for finding in d.get("outside_physics") or []:
        steps.append(Step((f"Check {effect_in_words(str(finding.get('effect')))} on the robot: the data fit it only "
                           "outside physics.",), kind="check"))
    return steps


def export_step(diagnosis_json: str | None) -> Step:
    """Loading the calibration into the controller: the ``export`` command of a diagnosis' JSON
    (None: ``DIAGNOSIS.json``, what ``--json FILE`` would write)."""
    name = shlex.quote(diagnosis_json) if diagnosis_json else "DIAGNOSIS.json"
    return Step(("Load the calibration into the controller: ", Code(f"tcr-accuracy export {name} --to calibration"),
                 " writes the calibration URDF, DH tables, the UR driver's file and the compensation filter, each with "
                 "what it reaches" + ("" if diagnosis_json else " (DIAGNOSIS.json: this run again with --json FILE)")
                 + "."))


def next_steps_lines(steps: list) -> list[str]:
    """The steps as the printed summary ends: a heading, then one numbered sentence a step, each
    command between backquotes."""
    return ["Next steps:"] + [f"  {i}. {step.text('`')}" for i, step in enumerate(steps, 1)]
