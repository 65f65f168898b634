"""Studies of the seed papers (Monte Carlo reproductions); not used by the estimators."""
