"""MAVLink at the edges (shell): the vehicle link and the GCS side, one module per microservice."""
