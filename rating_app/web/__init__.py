"""The blueprints: the rater API, the pages and the admin dashboard."""
