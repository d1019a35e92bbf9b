"""What a run shows a person: report.md built from sections, the verdict in words, and the figures."""
