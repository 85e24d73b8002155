"""Classical and model-based controllers: PID, linear system identification + LQR."""
