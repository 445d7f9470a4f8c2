"""tubejax."""
