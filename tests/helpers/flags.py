"""The export's `flags` cell as a test of the viewing rule reads it: without `failed_catch`, which marks the rows of a
rater the exclusion rule excludes (issue 55 item 1); those tests answer catch trials at random."""


def video_flags(cell: str) -> str:
    return ";".join(f for f in cell.split(";") if f != "failed_catch")
