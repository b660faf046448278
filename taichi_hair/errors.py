"""Exceptions raised by taichi-hair."""


class SimulationDivergedError(RuntimeError):
    """A step produced a non-finite value.

    The solver restores the begin-of-step state before raising, so the state
    handed to :meth:`SolverADMM.step` is still the last valid one.

    Attributes:
        strand: index of the first strand (in builder order) holding a
            non-finite value.
        field: name of the offending state quantity (``"vertex_position"``,
            ``"edge_twist"``...).
        step: the solver's step counter when it happened.
    """

    def __init__(self, strand: int, field: str, step: int):
        self.strand = strand
        self.field = field
        self.step = step
        super().__init__(
            f"simulation diverged at step {step}: strand {strand} has a non-finite {field}; "
            "the state was restored to the beginning of the step (try a smaller time step, "
            "more solver iterations or substeps, or check the material parameters)"
        )
