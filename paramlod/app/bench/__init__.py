"""paramlod bench: scenarios, measurements, reports."""
