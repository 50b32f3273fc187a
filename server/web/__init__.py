"""The service's web pages (issue 27). STAND-IN of branch webresult: the `webjobs` branch owns this package's
shell (pages.py, api.js, base.css); at merge keep theirs and drop this file's stand-in."""
