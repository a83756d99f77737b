"""Results as files: the one reader of the JSON results the commands and scripts write.

A diagnosis, an ISO 9283 evaluation, a comparison of two campaigns, an export's accuracy of each
delivered form (``accuracy.json``, kind "export"): each is written to JSON and
read back through this package, which checks a file whole before anything uses it (its schema,
its figures against each other, one copy of each number, its robot against its source, its
parameters against their effects' physics on the robot). The command line and a Python script
read alike: :func:`~tcr_accuracy.results.types.read_result` (``tcr_accuracy.read_result``)
returns the typed result, :func:`read_result_document` the checked document. It sits above the
layers whose results it reads (``diagnosis``, ``iso9283``, ``asbuilt``) and below ``view``,
which draws them.
"""

from .files import check_physics, read_result_document, schema_of, validate_result
from .kinds import KINDS, kind_of, kind_or_none

__all__ = ["KINDS", "check_physics", "kind_of", "kind_or_none", "read_result_document", "schema_of",
           "validate_result"]
