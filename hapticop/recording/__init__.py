"""Recording a run's streams to MCAP, and reading, recovering and plotting what was recorded."""
