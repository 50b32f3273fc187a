"""The service's web pages (issue 27): static HTML and our own ES-module JavaScript, no build step, no CDN.

Every page reads its data from the JSON API (/v1/...) with the API key the user typed (sessionStorage),
so tenants are kept apart exactly as the API keeps them (pages.py).
"""
