"""A finished sweep's reports: its trials read back from MLflow, and what the parent run shows of them."""
