"""The fleet dashboard (``suspid dashboard``): a Flask application over the monitoring database."""
