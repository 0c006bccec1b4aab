"""Trained runs on the Hugging Face Hub: ``orbitmodel push RUN REPO_ID`` uploads a run folder as a
model repo with a generated card; every ``from_pretrained`` (and ``eval closed-loop``, and the
``planner`` pilot's ``run=``) loads such a repo by its id (``orbitmodel.runs.resolve_run``)."""
