"""Motion generation: BVH import, features, FL and MoGlow flows, training, sampling, stimuli."""
