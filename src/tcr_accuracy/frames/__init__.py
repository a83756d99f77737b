"""The measurement frames: the instrument's frame registered to the robot's base.

One home for every transform between the tracker (camera, total station) and the robot:

* :mod:`~tcr_accuracy.frames.rigid` -- the closed-form rigid fit (Kabsch), the one of the project;
* :mod:`~tcr_accuracy.frames.registration` -- the tracker frame and the TCP offset refined on
  the ``frames`` effect (:class:`Registration`, :func:`register_tracker`);
* :mod:`~tcr_accuracy.frames.sessions` -- each session's own tracker frame;
* :mod:`~tcr_accuracy.frames.drift` -- the tracker's drift seen by base references;
* :mod:`~tcr_accuracy.frames.noise` -- the instrument's noise where the frames reveal it.

Transforms are named ``trackerMbase`` (base-frame points into the tracker frame), as Pinocchio
names its placements. Lengths in m, angles in rad.
"""
