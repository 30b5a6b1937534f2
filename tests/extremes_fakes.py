"""Adapters for the predictability check of tests/test_extremes.py, loaded as "extremes_fakes:Class"."""
from impactval.engines.fake_ import HertzSpringAdapter
from impactval.reference.hertz import ContactLaw


class Jumpy(HertzSpringAdapter):
    """The closed form, but the contact law's coefficient jumps by 10 % when v0 exceeds 1 m/s by more
    than 5e-7 (relative): a metric that is not a smooth function of its input."""

    name = "jumpy"

    def contact_law(self, scene, settings):
        law = super().contact_law(scene, settings)
        return ContactLaw(law.kind, 1.1 * law.coefficient) if scene.ball.velocity > 1.0 + 5e-7 else law
