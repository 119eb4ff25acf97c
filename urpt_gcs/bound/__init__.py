"""The certified lower bound: relaxations of the continuous problem that no flight beats."""
