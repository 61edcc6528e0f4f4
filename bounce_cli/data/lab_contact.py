"""The simulated lab's contact search constants, shared by its Python loop
(``simulated_lab``) and its compiled one (``compiled_lab``), so that neither imports the
other's module for them and both stop at the same gap."""

#: the contact iteration stops when the gap is below this (m) and polishes with one Newton step
CONTACT_TOLERANCE_M = 1e-12
#: safe steps allowed per flight before giving up (typical flights take 10-40)
MAX_CONTACT_STEPS = 20_000
