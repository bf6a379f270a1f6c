"""Motion data on disk: preparing the locomotion data set, the one dataset.npz reader, and reading other tools'
and other skeletons' motion (imported systems, motion files of any skeleton)."""
