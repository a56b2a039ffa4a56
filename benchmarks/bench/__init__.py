"""rmm-bench: run guardians over seeded episodes, store results, report Table I."""
