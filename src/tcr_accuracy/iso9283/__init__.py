"""ISO 9283:1998 performance tests of a robot: the one home of the standard's tests.

- :mod:`.formulas`: the pose characteristics from repeated readings (AP, RP, vAP, AD, RD,
  stabilisation time and overshoot);
- :mod:`.plan`: the test cube, its five poses, their joints, the cycle order and the test
  conditions;
- :mod:`.evaluate`: a measured pose test registered into the base frame and evaluated, before
  and (predicted) after compensation with a diagnosis' model;
- :mod:`.path`: the path tests (the standard's test paths in the cube's plane, AT, RT, corner
  deviations and path velocity characteristics).

Layer: above ``prediction`` and ``asbuilt``, below ``view`` and ``cli``. Lengths are metres,
angles radians, times seconds; nothing here prints.
"""
