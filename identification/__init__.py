"""identification package: pass logs -> pre-processing -> OKID -> ERA / ERA-DC -> Kalman predictor -> model files.

Public API (import from the modules):

* :class:`identification.passlog.PassLog` - the pass-log contract;
* :class:`identification.data.IOData` - multi-experiment input/output data on one sample time;
* :class:`identification.preprocess.Preprocessing`, :func:`~identification.preprocess.passes_to_iodata`;
* :class:`identification.okid.OKID` - ``OKID(...).fit(data)`` sets ``markov_parameters_``,
  ``hankel_singular_values_``, ``model_``;
* :func:`identification.era.era`, :func:`~identification.era.select_order`,
  :func:`~identification.era.modal_singular_values`, :func:`~identification.era.emac`;
* :func:`identification.estimator.kalman_gain` - stabilising Riccati predictor gain;
* :class:`identification.model.Model` - ``save`` / ``load`` / ``to_statespace``;
* :class:`identification.predictor.KalmanPredictor` - the model's estimator, one step at a time;
* :func:`identification.validation.validate` - free-run / one-step fits, error bias and std;
* :func:`identification.tractor.identify_tractor` - local, velocity-invariant and central models;
* ``identification`` command (:mod:`identification.cli`): ``convert``, ``okid``, ``fit``, ``validate``, ``report``.
"""
