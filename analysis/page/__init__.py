"""What every report page shares: its HTML, figures, the text of a study of your own, the methods paragraph."""
