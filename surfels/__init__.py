"""Blue surfels (progressive blue-noise sampling and the prefix renderer); see issue tracker."""
