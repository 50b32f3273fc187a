"""HTTP routes of the service, one module per resource: jobs, their results, the service itself."""
