"""An independent generator of drilling recordings and simulations for the diagnosis benchmark.

It shares no code with ``femstudy`` (it imports nothing from it) and, on purpose, none of
``femstudy.recordings.synthetic``'s functional forms: the drilling physics is the thesis's
(cutting loads growing while the drill point enters, chip-evacuation growth with depth,
breakthrough into cancellous bone), written again with other forms, and the rig effects are
the ones a real recording has and the femstudy generator does not (coloured amplifier noise,
quantisation, tare offsets, warm-up drift, stick-slip and swept feed pulsation, ...).

- :mod:`bench.independent.physics`: the drill, the bone layers and the load history.
- :mod:`bench.independent.sensor`: what the load cell and amplifier add.
- :mod:`bench.independent.cases`: the benchmark classes, their ground truth, and the files.
"""
