"""The rooms of the big parts, in order (docs/ARCHITECTURE.md): the architecture test enforces the order, and the
README layout test checks that ARCHITECTURE names every room."""

# Each big part's rooms (subpackages), lowest first: a room may import those before it, never one after it. The
# part's top-level modules (its commands: the main job, the report, the app's factory) may import every room.
ROOMS = {
    "generation": ("motion", "data", "metrics", "models", "training", "sampling", "stimuli", "own_study", "challenge"),
    "rating_app": ("store", "guard", "media", "pairing", "designs", "trials", "operations", "web", "simulate"),
    "analysis": ("data", "stats", "page", "designs", "board"),
}
