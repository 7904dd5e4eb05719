"""Driver for the Airelectronics U-Camera gimbal (UCSP over RS-232)."""
