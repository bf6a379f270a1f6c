"""Plain, slow implementations that the product's fast ones are checked against (tests) and timed against
(bench/). None of this is used by the product."""
