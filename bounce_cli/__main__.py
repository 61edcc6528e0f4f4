from .interrupts import main

main()
