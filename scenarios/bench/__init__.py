"""The closed loop: the Testbench, its vehicles, observers, field policies and map sharing."""
