"""Learning a force-model basis from flight logs (``vtoladapt learn-basis``).

:mod:`.data` turns logs into tasks (one per flight: what the flight computer had, the force it
measured), :mod:`.meta` fits the shared network by meta-learning (each flight's linear weights in
closed form inside the loss), :mod:`.flights` flies training draws of a campaign file with
held-out conditions, :mod:`.basis` puts it together and writes the basis file that
:mod:`vtoladapt.bases.learned` flies, :mod:`.cli` is the command.
"""
