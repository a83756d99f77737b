"""The calibrated robot: one home for the as-built model and every form it leaves the tool in.

Layer: after ``prediction`` (it may import ``model``, ``io``, ``effects``, ``frames``,
``analysis``, ``diagnosis`` and ``prediction``); ``view`` and ``cli`` build on it.

* :mod:`~tcr_accuracy.asbuilt.model` -- :class:`AsBuiltModel`, the full fitted model (every effect);
* :mod:`~tcr_accuracy.asbuilt.model_file` -- its one file format, written by ``export`` and
  ``diagnose --as-built-urdf`` and read by :func:`load_as_built` (``docs/as-built-format.md``);
* :mod:`~tcr_accuracy.asbuilt.diagnosis_file` -- the model in a ``diagnose --json`` result, read strictly;
* :mod:`~tcr_accuracy.asbuilt.refit` -- the geometry a URDF can carry, refitted to the full model;
* :mod:`~tcr_accuracy.asbuilt.urdf` -- that geometry as a URDF (the measured point a frame of its own);
* :mod:`~tcr_accuracy.asbuilt.dh` -- DH and modified DH tables, Hayati's beta for parallel axes;
* :mod:`~tcr_accuracy.asbuilt.maker_dh` -- the makers' published tables (UR, Franka) and the as-built
  robot in their convention;
* :mod:`~tcr_accuracy.asbuilt.ur_calibration` -- the UR ROS 2 driver's kinematics calibration file;
* :mod:`~tcr_accuracy.asbuilt.compensation_filter` -- corrected commands for a controller that takes no model;
* :mod:`~tcr_accuracy.asbuilt.accuracy` -- what each form reaches on measured positions;
* :mod:`~tcr_accuracy.asbuilt.export` -- all of the above for one diagnosis (:func:`build_export`).

Nothing here writes a file or prints: the commands do (``tcr_accuracy.cli.export``).
"""
