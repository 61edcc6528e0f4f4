from .runtime.interrupts import main

main()
