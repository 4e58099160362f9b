"""Classical navigation controllers that read only a real robot's sensors."""
