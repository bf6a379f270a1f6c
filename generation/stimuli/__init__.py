"""The stimuli files of a study: items, manifest and tables, tool-made catch clips, and the pool of render workers."""
