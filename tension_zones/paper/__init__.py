"""The paper's reproduction: identification of its unreported segment, its figures and tables."""

from .. import _config  # noqa: F401  (float64 before any array is made)
from ._identify import PAPER_TABLE, identify
from ._reproduce import STEPS, reproduce

__all__ = [
    "PAPER_TABLE",
    "STEPS",
    "identify",
    "reproduce",
]
