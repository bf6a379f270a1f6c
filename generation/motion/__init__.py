"""Motion as joints: the BVH reader, skeletons, resampling, the 21-joint features and the rigid-bone fit."""
