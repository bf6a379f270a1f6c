"""The stimuli files of a study: items, manifest and tables, tool-made catch clips, the pool of render workers,
and the main job's closing summary."""
