"""Publishing a dataset to the Hugging Face Hub: ``push`` (and ``preview`` for a dry run)."""

from orbitdata.publish.hub import HubError, PushOptions, PushRefused, PushResult, preview, push
from orbitdata.publish.plan import UploadFile, UploadPlan, plan_upload

__all__ = [
    "HubError",
    "PushOptions",
    "PushRefused",
    "PushResult",
    "UploadFile",
    "UploadPlan",
    "plan_upload",
    "preview",
    "push",
]
