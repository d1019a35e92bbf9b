within;
model Distillation "Top composition of a column: slow lag and dead time on the log composition (Skogestad 1997)"
  // Same equations as model.c: T dX/dt = a + b R(t - L) - X, x_D = 100 / (1 + exp(-X)).
  parameter Real a = -3.8;
  parameter Real b = 4.0 "min/kmol";
  parameter Real T(unit = "s") = 864;
  parameter Real L(unit = "s") = 180;
  input Real R(start = 2.0) "Reflux, kmol/min";
  output Real x_D "Top composition, mol %";
protected
  Real X(start = 4.2, fixed = true) "Logarithmic composition";
equation
  T * der(X) = a + b * delay(R, L) - X;
  x_D = 100 / (1 + exp(-X));
end Distillation;
