"""The wire's tension: the tensioner and the free span as linear systems of
the take-up speed (:mod:`~winder.tension.tensioner`), stepped exactly
(:mod:`~winder.tension.lti`), and a layer's tension over a turn predicted
before it is wound (:mod:`~winder.tension.predict`). Plain numpy; the
geometry and the wire's material come from :mod:`winder.motion`."""
