"""Validating a dataset folder (or a downloaded Hub snapshot) against the contract.

    from orbitdata.validate import validate, ValidateOptions
    report = validate("./orbit_planner", ValidateOptions(quick=False, workers=0))
    print(report.render()); report.ok; report.failed()

The checks are listed in :mod:`orbitdata.validate.checks`; each module ``checks_*`` owns a
group of them, :mod:`~orbitdata.validate.rowgroup` is the unit of parallel work and
:mod:`~orbitdata.validate.runner` puts it together. Names import on first use.
"""

_LAZY = {
    "CHECKS": "orbitdata.validate.checks",
    "Check": "orbitdata.validate.checks",
    "Finding": "orbitdata.validate.report",
    "Report": "orbitdata.validate.report",
    "ValidateOptions": "orbitdata.validate.runner",
    "validate": "orbitdata.validate.runner",
}


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'orbitdata.validate' has no attribute {name!r}")


__all__ = sorted(_LAZY)
