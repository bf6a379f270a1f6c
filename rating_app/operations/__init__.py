"""What the researcher runs: exports, backups, the dashboard's figures, warnings, and conditions that join or leave."""
