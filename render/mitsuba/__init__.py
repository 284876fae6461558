"""The Mitsuba 3 / mitransient reference: scene export, render passes and the reference stage."""
