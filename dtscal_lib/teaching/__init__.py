"""The teaching layer: what the course notebooks, the student and the instructor's hand-out use.

* :mod:`~dtscal_lib.teaching.course`: the notebooks' plumbing, figures and experiments
* :mod:`~dtscal_lib.teaching.selfcheck`: the student's self-checks and the named mistakes
* :mod:`~dtscal_lib.teaching.release`: solutions -> student notebooks, the hand-out
* :mod:`~dtscal_lib.teaching.workspace`: the student's workspace copy and its updates
* :mod:`~dtscal_lib.teaching.handin`: the hand-in zip
* :mod:`~dtscal_lib.teaching.command`: registers ``course``, ``handin``, ``release`` and ``handout`` on ``dtscal``

The rule: the calibration library (everything in ``dtscal_lib`` outside ``teaching/`` and ``grading/``) never
imports this package; ``tests/test_import_cycles.py`` checks it. The teaching layer builds on the library, and
neither it nor the grader (``grading/``) imports the other: both name mistakes with the catalogue
:mod:`dtscal_lib.mistakes` and read the exercises' rules from :mod:`dtscal_lib.exercise_rules`.
"""
