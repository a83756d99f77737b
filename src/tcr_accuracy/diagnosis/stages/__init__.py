"""The diagnosis as stages, each a function with a typed, frozen result in SI units.

:class:`~tcr_accuracy.diagnosis.diagnose.GapDiagnosis` runs them in this order; each can be
run and inspected on its own (``diagnosis.stages`` keeps every stage's result):

1. :mod:`.register` -- the tracker frame of each session, the tracker's drift, the measured
   targets in the robot's base frame (:class:`~.register.RegisteredMeasurements`);
2. :mod:`.candidates` -- every effect linearised on the measured poses, which can be tried and
   why not the others, the folds, the instrument's noise where the data's redundancy gives it
   (:class:`~.candidates.CandidateSet`);
3. :mod:`.select` -- forward selection on held-out error, the effects of last resort, the
   one-standard-error swaps, backward elimination, what the data cannot tell apart
   (:class:`~.select.Selection`); with several sessions, :mod:`.setup` chooses what each owns
   (a tracker frame, a TCP offset, both or neither) before it and judges it again after
   (:class:`~.setup.SessionSetup`);
4. :mod:`.attribute` -- the primary effect or group, the shrink table in the order of
   explanation, the selection's stability, what the data fit only outside physics
   (:class:`~.attribute.Attribution`), and where the first-order effect models end;
5. :mod:`.residual` -- where the gap lies, the noise, whether structure or scatter remains,
   the held-out figures per session and measured frame (:class:`~.residual.ResidualAnalysis`);
6. :mod:`.parameters` -- the fitted values with their intervals and physical ranges, the
   as-built geometry and the tracker frame (:class:`~.parameters.FittedParameters`).

The tools the stages use live beside them in :mod:`tcr_accuracy.diagnosis` (the fit engine,
identifiability, ambiguity, attribution, uncertainty, structure, residuals).
"""
