"""Tests of host/: the host pipeline (images, planes, words, references, runs, datasets, sweeps)."""
