"""What a request may bring: the abuse limits shared by every blueprint and the checks of a rater's JSON body."""
