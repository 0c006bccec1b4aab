"""Stage II: the physics probe that reads states out of the world model's imagined latents.

``integrator`` (batched rigid-body kinematics), ``model`` (:class:`PhysicsProbe`), ``variants``
(the run's named probes: the paper's, the thrust-only one, the latent-only candidates),
``baselines`` (the state-only MLP and constant velocity), ``train`` (``orbitmodel probe``),
``metrics``, ``table1``, ``evaluate`` and ``figures`` (``orbitmodel eval probe``: the paper's
Table I with the rows to read it against, and Figure 5).
"""

from orbitmodel.probe.model import PhysicsProbe

__all__ = ["PhysicsProbe"]
