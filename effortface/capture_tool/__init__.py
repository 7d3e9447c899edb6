"""Stage 1, capture: heart-rate straps over serial ports, webcam video, crash-safe session folders."""
