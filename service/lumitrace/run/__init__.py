"""Running a trace: settings that check themselves, sessions of growing iterations,
worker pools, and the throughput benchmark."""
