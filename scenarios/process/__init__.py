"""Process plumbing: worker pools, progress lines and staged output directories."""
