"""Host: images, features, likelihoods, reference, runs, metrics, plots."""
