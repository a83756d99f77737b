"""tcr-accuracy: motion accuracy of serial robots, built on Pinocchio.

Layers (each imports only from those before it): ``robot`` -> ``errors`` ->
``kinematics`` -> analyses -> edges (``report``, ``viewer``, ``cli``). See the
project's DESIGN notes and README.
"""

__version__ = "0.1.0"
