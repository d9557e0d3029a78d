"""A second algorithm as a plug-in (tests/test_algorithms.py registers it): plain proximal gradient, no momentum,

    x⁺ = prox_{s·g}(x − s·∇f(x)),

one module against clsdcam.algorithms.base, nothing else of the package touched."""
from clsdcam.algorithms.base import Algorithm, place, ratio


class ProximalGradient(Algorithm):
    name = "pgm"

    def __init__(self, backend, x0, step: float, rules):
        super().__init__(backend, x0, step, rules)
        self.x = self.z = None
        self.x, self.z = place(backend, [self.x, self.z], [x0, x0])

    def iterate(self, problem) -> dict:
        be = self.backend
        data = problem.gradient_step(self.x, self.z, self.step)
        before = be.copy(self.x)
        problem.prox(self.z, self.step, self.x)
        moved = be.axpy(-1.0, before, self.x, out=before)
        return {"data": data, "change": ratio(be.vdot(moved, moved), be.vdot(self.x, self.x))}

    def reset(self, point) -> None:
        self.backend.copy(point, out=self.x)

    def move(self, mapping) -> None:
        x = mapping(self.x)
        self.x, self.z = place(self.backend, [self.x, self.z], [x, x])
