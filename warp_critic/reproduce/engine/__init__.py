"""Engine: a general stage workflow -- stage directories, scheduling, executors, ledger, carry; it knows no paper and no method."""
