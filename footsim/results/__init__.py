"""Study results: the statistics over training seeds (:mod:`footsim.results.stats`) and the study
plan, evaluation, data files and generated results page of ``footsim-reproduce``
(:mod:`footsim.results.reproduce`)."""
