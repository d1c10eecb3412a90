"""Tests of bayesmachine/columns: each evidence column kind, across every layer that builds its words."""
