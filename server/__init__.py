"""The HTTP service: FastAPI routes over a SQLite job store, jobs run in worker processes.

Depends on schemas and engine, never on clients or the command line. Importing this
package is cheap (worker processes import server.worker): the web app is in server.app.
"""
