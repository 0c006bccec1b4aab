"""Validating a dataset folder (or a downloaded Hub snapshot) against the contract.

    from orbitdata.validate import validate, ValidateOptions
    report = validate("./orbit_planner", ValidateOptions(quick=False, workers=0))
    print(report.render()); report.ok; report.failed()

The checks are listed in :mod:`orbitdata.validate.checks`; each module ``checks_*`` owns a
group of them, :mod:`~orbitdata.validate.rowgroup` is the unit of parallel work and
:mod:`~orbitdata.validate.runner` puts it together.
"""

from orbitdata.validate.checks import CHECKS, Check
from orbitdata.validate.report import Finding, Report
from orbitdata.validate.runner import ValidateOptions, validate

__all__ = ["CHECKS", "Check", "Finding", "Report", "ValidateOptions", "validate"]
