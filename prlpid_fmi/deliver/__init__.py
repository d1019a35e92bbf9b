"""Which controller is deployed and why: the evidence (replays, Monte-Carlo set, margins), the candidate tables, and
the rule."""
