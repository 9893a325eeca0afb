"""Campaigns: many seeds, policies and sampled variations; tables, statistics, comparison."""
