"""What every part shares and nothing else: the contracts between the parts and their conventions.

- `cli`: the command-line convention: one-line user errors (`UserError`, exit code 2), bounded flag types, `run`.
- `clip`: the clip file format (CONTRACTS §1) and its limits, and the one cap on a mesh's vertices.
- `study`: the study's facts: conditions, roles, catch rules and the rater exclusion, designs, clip ids, metrics.
- `tables`: CSV reading for the parts (the metrics.csv reader among them).
- `user_files`: every file a command reads from a user, read as hostile (regular files only, caps, the JSON depth
  scan, formula cells defused).
- `votes`: what a pairwise vote is, as the app stores it and the analysis reads it.
- `skeleton_names`: a joint's side, finger or face, from its name.
- `moved`: commands that moved, and the one line their old path answers.
- `pair_posterior`: the Bradley-Terry posterior of a growing pairwise study, a pair's information, the stopping rule.
- `colours`: a person's drawing colour as the files carry it and as the rater's page names it.
- `blas`: one BLAS thread around small, repeated fits (the report's models, the two-sample tests, mesh skinning).
- `ranks`: ranks with ties averaged, and the AUC they give (the two-sample tests, the blinding check, the simulated
  raters), in numpy alone.
- `ports`: a free loopback port below the kernel's ephemeral range, for a server started for a moment.
- `whole_files`: an output written whole or not at all (a hidden temporary file beside it, renamed over it).

`core` imports nothing from the four parts (generation, rendering, rating_app, analysis); they import it.
"""
