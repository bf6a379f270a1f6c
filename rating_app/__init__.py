"""The crowd rating web app (Flask): sessions, familiarisation, rating trials, admin and export."""
