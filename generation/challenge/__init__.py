"""Running a challenge: teams' submissions checked against the released test inputs (docs/challenge.md).

`layout` walks a team's folder as hostile (what is there, and what should not be), `checks` reads each motion file
within bounds and checks it against its item's speech, and `intake` is the command that runs both over one team or a
whole challenge and writes each team's report (`intake_page` draws it).
"""
