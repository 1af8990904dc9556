"""The paper's reproduction: identification of its unreported segment, its figures and tables."""

from ._identify import PAPER_TABLE, identify
from ._reproduce import STEPS, reproduce
