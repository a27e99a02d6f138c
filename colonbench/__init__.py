"""colonbench: synthetic colonoscopy coverage data and a coverage-estimation benchmark.

The package is one import namespace mapped onto the data-flow folders of the
repository::

    datagen/     -> colonbench.datagen     procedural colons, camera, holes, segments
    completion/  -> colonbench.completion  the paper's learned completion method
    baselines/   -> colonbench.baselines   thresholding and 2D-unwrapping baselines
    benchmark/   -> colonbench.benchmark   evaluation harness, leaderboards, figures

Geometry is in millimetres everywhere a user sees it.
"""

from colonbench._version import __version__
from colonbench.errors import ColonbenchError, InputError

__all__ = ["__version__", "ColonbenchError", "InputError"]
