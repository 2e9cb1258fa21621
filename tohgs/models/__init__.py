"""Components, the trainable networks (:mod:`tohgs.models.component`): the diffusers, PointNet++, the one
training loop and the one checkpoint format."""
