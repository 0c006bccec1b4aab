"""Validating a dataset folder (or a downloaded Hub snapshot) against the contract.

    from orbitdata.validate import validate, ValidateOptions
    report = validate("./orbit_planner", ValidateOptions(quick=False, workers=0))
    print(report.render()); report.ok; report.failed()

The checks are listed in :mod:`orbitdata.validate.checks`; each module ``checks_*`` owns a
group of them, :mod:`~orbitdata.validate.rowgroup` is the unit of parallel work and
:mod:`~orbitdata.validate.runner` puts it together. Names import on first use.
"""

from orbitdata.lazy import lazy_getattr

_LAZY = {  # name -> the module that defines it
    **dict.fromkeys(("CHECKS", "Check"), "orbitdata.validate.checks"),
    **dict.fromkeys(("Finding", "Report"), "orbitdata.validate.report"),
    **dict.fromkeys(("ValidateOptions", "validate"), "orbitdata.validate.runner"),
}

__getattr__ = lazy_getattr(__name__, _LAZY)
__all__ = sorted(_LAZY)
